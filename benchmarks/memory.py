"""Memory per texel: the bake's estimate (memory.py) against the peak it really reached.

    python benchmarks/memory.py [--resolution 2048] [--estimators disc_index,sphere_cache,...]
                                [--photons 20000] [--no-denoise] [--gutter 0.05] [--json OUT]
                                [--directional none|sh|dominant] [--shadowmask]

Each bake runs in a fresh process (its peak resident memory is its own): once at 32² and once at
--resolution, on a floor under a ceiling lit by a point light (one baked lightmap whose UVs fill
the square but a --gutter, 5 %: texels are then 0.81 of the pixels). Bytes per texel = (peak at
--resolution − peak at 32²) / texels, so interpreter, kernels, Embree and photon batches cancel
out; the estimate's bytes per texel are taken the same way. A sampler thread also records which
phase of the bake (rasterise, direct, clearance, rise, build, trace+estimate, images, denoise) held
the peak, and the line the main thread was on. Prints a table, writes JSON
(default benchmarks/results/memory.json; with --record also benchmarks/measured/memory.json, from
which the docs' figures are rendered: measured.py). --directional and --shadowmask (the lamp's) bake those maps
too: their parts of the estimate count with the texels'.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

ESTIMATORS = ["disc_index", "sphere_cache", "detp", "photon_map", "hybrid"]
TINY = 32
# The brute-force oracle refuses more than 4e10 segment–disc tests: fewer photons for it.
PHOTONS = {"detp": 4000}


def _scene(resolution: int, gutter: float = 0.05):
    import numpy as np

    from detp_bake.scene import BakeObject, PointLight, Scene

    def plane(z, flip):
        p = np.array([[[-1, -1, z], [1, -1, z], [1, 1, z]], [[-1, -1, z], [1, 1, z], [-1, 1, z]]], np.float64)
        # UVs inset (5 %): a gutter for dilation and the denoiser's fill, as real charts have.
        uv = gutter + (1 - 2 * gutter) * np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], np.float64)
        if flip:
            p, uv = p[:, [0, 2, 1]], uv[:, [0, 2, 1]]
        n = np.broadcast_to([0.0, 0.0, -1.0 if flip else 1.0], p.shape).copy()
        return p, n, uv

    floor, ceiling = plane(0.0, False), plane(1.0, True)
    return Scene(positions=np.concatenate([floor[0], ceiling[0]]), normals=np.concatenate([floor[1], ceiling[1]]),
                 uvs=np.concatenate([floor[2], ceiling[2]]), albedo=np.full((4, 3), 0.5), emission=np.zeros((4, 3)),
                 objects=[BakeObject("Floor", 0, 2, resolution, True), BakeObject("Ceiling", 2, 2, 4, False)],
                 lights=[PointLight("Lamp", np.array([0.0, 0.0, 0.5]), np.full(3, 50.0))],
                 world=np.zeros(3), default_bounces=2)


def _child(estimator: str, resolution: int, photons: int, denoise: bool, gutter: float,
           directional: str = "none", shadowmask: bool = False) -> dict:
    from detp_bake.run import bake, finishing, memory, pipeline
    from detp_bake.lightmap import denoise as denoise_mod, texels
    from detp_bake.transport import direct
    from detp_bake import estimators
    from detp_bake.estimators import rise

    phase = ["setup"]
    peaks: dict = {}
    seconds: dict = {}
    done = threading.Event()
    page = os.sysconf("SC_PAGE_SIZE")

    main = threading.get_ident()
    where = [0, []]

    def sample():
        with open("/proc/self/statm") as f:
            while not done.is_set():
                f.seek(0)
                rss = int(f.read().split()[1]) * page
                peaks[phase[0]] = max(peaks.get(phase[0], 0), rss)
                if rss > where[0]:  # where the main thread was at the peak so far
                    frame = sys._current_frames().get(main)
                    stack = traceback.extract_stack(frame)[-6:] if frame is not None else []
                    where[0], where[1] = rss, [f"{Path(f.filename).name}:{f.lineno} {f.name}" for f in stack]
                time.sleep(0.005)

    def step(module, attr, name):
        """Name the phase while module.attr runs (the pipeline looks these up at call time)."""
        inner = getattr(module, attr)

        def wrapped(*args, **kwargs):
            outer, phase[0] = phase[0], name
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                seconds[name] = seconds.get(name, 0.0) + time.perf_counter() - t0
                phase[0] = outer
        setattr(module, attr, wrapped)

    for module, attr, name in ((texels, "rasterise", "rasterise"), (direct, "direct_irradiance", "direct"),
                               (texels, "tangent_clearance", "clearance"), (pipeline, "own_surface_rise", "rise"),
                               (estimators, "create", "build"), (finishing.Finishing, "images", "images"),
                               (denoise_mod, "denoise_lightmap", "denoise")):
        step(module, attr, name)

    def progress(p):
        if p.phase in ("trace", "estimate") and phase[0] not in ("images", "denoise"):
            phase[0] = "trace+estimate"

    # Every texel a site (sites.py): the most an estimator can hold, which the estimate assumes.
    settings = bake.BakeSettings(estimator=estimator, photons=photons, resolution=resolution, seed=1,
                                 denoise=denoise, indirect_spacing=1, directional=directional,
                                 shadowmask=("Lamp",) if shadowmask else ())
    watcher = threading.Thread(target=sample, daemon=True)
    watcher.start()
    t0 = time.perf_counter()
    r = bake.compute(_scene(resolution, gutter), settings, progress)
    seconds["total"] = time.perf_counter() - t0
    done.set()
    watcher.join()
    parts = r.memory["parts_mb"]
    texel_mb = sum(v for k, v in parts.items() if k in ("texels", "lightmap images", "denoiser",
                                                          "directional maps", "shadowmask")
                   or k.startswith("estimator"))
    return {"estimator": estimator, "resolution": resolution, "texels": len(r.texels), "peak": memory.peak_bytes(),
            "estimate": r.memory["estimate_mb"] * 1e6, "estimate_texels": texel_mb * 1e6,
            "phases": peaks, "seconds": seconds, "peak_at": where[1], "segments": r.stats.segments}


def _run_child(estimator: str, resolution: int, photons: int, denoise: bool, gutter: float,
               directional: str = "none", shadowmask: bool = False) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, __file__, "--child", estimator, str(resolution), str(photons),
                           str(int(denoise)), str(gutter), directional, str(int(shadowmask))],
                          capture_output=True, text=True, env=env, cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"{estimator} at {resolution}: failed\n{proc.stdout[-2000:]}{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def measure(estimator: str, resolution: int, photons: int, denoise: bool = True, gutter: float = 0.05,
            directional: str = "none", shadowmask: bool = False) -> dict:
    """Bytes per texel of `estimator`: estimated and measured, from a tiny and a large bake."""
    extra = (directional, shadowmask)
    _run_child(estimator, TINY, photons, denoise, gutter, *extra)  # warms the kernel cache
    small = _run_child(estimator, TINY, photons, denoise, gutter, *extra)
    large = _run_child(estimator, resolution, photons, denoise, gutter, *extra)
    texels = large["texels"] - small["texels"]
    peak_phase = max(large["phases"], key=large["phases"].get)
    return {"estimator": estimator, "resolution": resolution, "texels": large["texels"],
            "directional": directional, "shadowmask": shadowmask,
            "coverage": large["texels"] / resolution ** 2,
            "estimate_per_texel": (large["estimate_texels"] - small["estimate_texels"]) / texels,
            "measured_per_texel": (large["peak"] - small["peak"]) / texels,
            "peak_mb": large["peak"] / 1e6, "estimate_mb": large["estimate"] / 1e6, "peak_phase": peak_phase,
            "phases_per_texel": {k: round((v - small["peak"]) / texels, 1) for k, v in large["phases"].items()},
            "peak_at": large["peak_at"],
            "seconds": large["seconds"], "segments": large["segments"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--resolution", type=int, default=2048)
    ap.add_argument("--estimators", default=",".join(ESTIMATORS))
    ap.add_argument("--photons", type=int, default=20000)
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "memory.json"))
    ap.add_argument("--no-denoise", action="store_true", help="bake without OIDN")
    ap.add_argument("--gutter", type=float, default=0.05, help="UV inset of the lightmap (0: no gutter)")
    ap.add_argument("--directional", default="none", choices=["none", "sh", "dominant"],
                    help="also bake directional maps (their estimate counts per texel)")
    ap.add_argument("--shadowmask", action="store_true", help="also bake the lamp's shadowmask")
    ap.add_argument("--record", action="store_true",
                    help="also write benchmarks/measured/memory.json, which the docs' figures are rendered from")
    ap.add_argument("--child", nargs=7, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        c = args.child
        print(json.dumps(_child(c[0], int(c[1]), int(c[2]), bool(int(c[3])), float(c[4]), c[5], bool(int(c[6]))),
                         allow_nan=False))
        return
    rows = []
    print(f"{'estimator':<13} {'texels':>10} {'estimate B/texel':>17} {'measured B/texel':>17} {'ratio':>6} "
          f"{'peak MB':>8}  peak phase, where")
    for name in args.estimators.split(","):
        row = measure(name, args.resolution, min(args.photons, PHOTONS.get(name, args.photons)), not args.no_denoise,
                      args.gutter, args.directional, args.shadowmask)
        rows.append(row)
        print(f"{name:<13} {row['texels']:>10,} {row['estimate_per_texel']:>17.0f} {row['measured_per_texel']:>17.0f} "
              f"{row['estimate_per_texel'] / row['measured_per_texel']:>6.2f} {row['peak_mb']:>8.0f}  "
              f"{row['peak_phase']}, {row['peak_at'][-1] if row['peak_at'] else '?'}", flush=True)
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    data = {"resolution": args.resolution, "photons": args.photons, "cores": os.cpu_count(),
            "denoise": not args.no_denoise, "gutter": args.gutter,
            "directional": args.directional, "shadowmask": args.shadowmask, "results": rows}
    out.write_text(json.dumps(data, indent=2, allow_nan=False))
    print(f"wrote {out}")
    if args.record:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        import measured
        print(f"recorded {measured.record('memory', data)}")


if __name__ == "__main__":
    main()
