"""Command line: `python -m detp_bake bake SCENE.blend ...` with the bpy wheel, and the same
parser behind Blender's `blender -b SCENE.blend -c detp_bake bake ...`.

Every check that can fail (settings, the .blend path, the output folder, object names, UV layers)
runs before tracing starts; progress goes to stderr, the report path to stdout.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from dataclasses import replace
from typing import Optional, Sequence

from . import __version__, bake as bake_mod, estimators, images, job as job_mod
from .errors import BakeCancelled, BakeError
from .estimators import KERNELS, EstimatorSettings, compare_defaults, names as estimator_names

# Every default and choice below comes from BakeSettings, EstimatorSettings and the estimator registry.
_B, _E = bake_mod.BakeSettings, EstimatorSettings


def build_parser(prog: str = "python -m detp_bake", with_scene_path: bool = True) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Bake diffuse irradiance lightmaps "
                                     "with photon density estimation (DETP).")
    parser.add_argument("--version", action="version", version=f"detp_bake {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bake", help="bake lightmaps for a .blend file")
    c = sub.add_parser("compare", help="bake the same photons with several estimators, side by side")
    c.add_argument("--estimators", nargs="+", default=compare_defaults(), metavar="ESTIMATOR",
                   help="estimators to compare; the first is the reference "
                                             "(default: %s)" % " ".join(compare_defaults()))
    for p in (b, c):
        _bake_arguments(p, with_scene_path)
    return parser


def _bake_arguments(b, with_scene_path):
    if with_scene_path:
        b.add_argument("scene", help="the .blend file to bake")
    b.add_argument("--objects", nargs="+", metavar="NAME", help="objects to bake (default: all visible meshes)")
    b.add_argument("--estimator", default=_B.estimator,
                   help=f"one of: {', '.join(estimator_names())} (default %(default)s)")
    b.add_argument("--photons", type=int, default=None,
                   help=f"photons to trace (default {bake_mod._si(_B.photons)}; with --target-noise or --time-limit, "
                        f"the most to trace, default {bake_mod._si(bake_mod.MAX_PHOTONS)})")
    b.add_argument("--target-noise", type=float, default=_B.target_noise, metavar="PERCENT",
                   help="trace photons in batches until every lightmap's relative noise is at most this")
    b.add_argument("--time-limit", type=float, default=_B.time_limit, metavar="SECONDS",
                   help="stop tracing before the bake has run this long (the photons so far stand for all)")
    b.add_argument("--direct", default=_B.direct, choices=bake_mod.DIRECT_MODES,
                   help="sampled: direct light by shadow rays, photons carry indirect light only (default); "
                        "photons: the estimator sees every segment (the paper's experiments)")
    b.add_argument("--direct-samples", type=int, default=_B.direct_samples,
                   help="shadow rays per texel for each light with extent (default %(default)s)")
    b.add_argument("--k", type=int, default=_E.k, help="photon map neighbours (default %(default)s)")
    b.add_argument("--radius-texels", type=float, default=_E.radius_texels,
                   help=f"DETP disc radius in texels (default {estimators.RADIUS_TEXELS_INDIRECT:g} with --direct "
                        f"sampled, {estimators.RADIUS_TEXELS_ALL:g} with --direct photons)")
    b.add_argument("--radius", type=float, default=_E.radius, help="DETP disc radius in metres (overrides texels)")
    b.add_argument("--q", type=float, default=_E.q, help="sphere cache radius ratio (default %(default)s)")
    b.add_argument("--kernel", default=_E.kernel, choices=KERNELS)
    b.add_argument("--resolution", type=int, default=_B.resolution, help="lightmap size in pixels (default %(default)s)")
    b.add_argument("--margin", type=int, default=_B.margin, help="dilation margin in pixels (default %(default)s)")
    b.add_argument("--bounces", type=int, default=_B.bounces,
                   help="diffuse bounces (default: the scene's Cycles Light Paths › Diffuse)")
    b.add_argument("--seed", type=int, default=_B.seed)
    b.add_argument("--threads", type=int, default=_B.threads, help="0 = all cores")
    b.add_argument("--uv-layer", default=None,
                   help="lightmap UV layer (default 'Lightmap', created with Lightmap Pack if missing)")
    b.add_argument("--out", required=True, help="output folder")
    b.add_argument("--format", default=",".join(_B.formats),
                   help=f"comma-separated: {','.join(images.WRITERS)} (default %(default)s)")
    b.add_argument("--half", action="store_true", help="write half-float EXR")
    b.add_argument("--denoise", action=argparse.BooleanOptionalAction, default=_B.denoise,
                   help="denoise the lightmaps with OIDN (default on; needs the pyoidn package)")
    b.add_argument("--keep-raw", action="store_true",
                   help="also write each lightmap before denoising, as <object>.<estimator>.raw.exr")
    b.add_argument("--apply", action="store_true", help="wire the lightmaps into the materials")
    b.add_argument("--save", default=None, metavar="OUT.blend", help="save the baked .blend here")


def settings_from_args(args) -> bake_mod.BakeSettings:
    formats = tuple(f.strip().lower() for f in args.format.split(",") if f.strip())
    return bake_mod.BakeSettings(
        estimator=args.estimator, photons=_photons(args), bounces=args.bounces, seed=args.seed,
        target_noise=args.target_noise, time_limit=args.time_limit, denoise=args.denoise, keep_raw=args.keep_raw,
        direct=args.direct, direct_samples=args.direct_samples,
        resolution=args.resolution, margin=args.margin, formats=formats, half=args.half,
        threads=args.threads,
        estimator_settings=EstimatorSettings(k=args.k, radius_texels=args.radius_texels,
                                             radius=args.radius, q=args.q, kernel=args.kernel))


def _photons(args) -> int:
    if args.photons is not None:
        return args.photons
    return bake_mod.MAX_PHOTONS if (args.target_noise or args.time_limit) else bake_mod.BakeSettings.photons


class StderrProgress:
    """Progress lines on stderr, at most one per phase every `interval` seconds."""

    def __init__(self, interval: float = 2.0):
        self.interval = interval
        self.last: dict = {}

    def __call__(self, p: bake_mod.Progress) -> None:
        now = time.monotonic()
        if p.fraction >= 1.0 or now - self.last.get(p.phase, -1e9) >= self.interval:
            self.last[p.phase] = now
            print(f"detp_bake: {p.message}", file=sys.stderr, flush=True)


def _log(msg: str) -> None:
    print(f"detp_bake: {msg}", file=sys.stderr, flush=True)


def _open_scene(args, settings, bl_scene):
    """Check the inputs, open the .blend (unless Blender has one open) and export it."""
    settings.validate()
    if args.apply and "exr" not in settings.formats:
        raise BakeError("--apply needs the exr format in --format")
    out_dir = images.check_writable_dir(args.out)
    if args.save:
        images.check_writable_dir(Path(args.save).resolve().parent)
    try:
        from . import blender
    except ImportError as exc:
        if exc.name != "bpy":
            raise
        raise BakeError("the 'bpy' module is not installed: run inside Blender or install the bpy wheel "
                        "(make demo sets one up)") from None
    if bl_scene is None:
        bl_scene = blender.open_blend(Path(args.scene))
    t0 = time.perf_counter()
    from .memory import geometry_budget
    scene = blender.export_scene(bl_scene, None, args.objects, args.uv_layer, settings.resolution, _log,
                                 max_bytes=geometry_budget(settings.memory_budget_mb) or None)
    _log(f"exported {scene.triangle_count} triangles, {len(scene.lights)} lights; "
         f"baking {sum(o.bake for o in scene.objects)} objects")
    return blender, bl_scene, scene, out_dir, time.perf_counter() - t0


def _run_job(job: job_mod.Job) -> job_mod.Result:
    """Run a job to its end, its progress and warnings on stderr; Ctrl-C cancels it."""
    progress = StderrProgress()
    events = job.events()
    try:
        for event in events:
            if isinstance(event, job_mod.Progress):
                progress(event)
            elif isinstance(event, job_mod.Warning):
                _log(f"warning: {event.message}")
            elif isinstance(event, job_mod.Error):
                raise BakeError(event.message)
            elif isinstance(event, job_mod.Cancelled):
                raise BakeCancelled()
            elif isinstance(event, job_mod.Result):
                return event
    except KeyboardInterrupt:
        job.cancel()
        for _ in events:  # the worker stops within a batch and removes what it staged
            pass
        raise BakeCancelled() from None
    raise BakeError("the job ended without a result")


def run_compare(args, bl_scene=None) -> int:
    """The same photons through several estimators: their lightmaps, compare.png, compare.json."""
    settings = settings_from_args(args)
    for name in args.estimators:
        replace(settings, estimator=name).validate()
    blender, bl_scene, scene, out_dir, export_seconds = _open_scene(args, settings, bl_scene)
    done = _run_job(job_mod.Job(scene, settings, out_dir, args.estimators, export_seconds=export_seconds))
    summary = done.comparison
    for name in summary["estimators"]:
        _log(f"{name}: estimate {summary['seconds'][name]:.2f} s, difference to {summary['reference']} "
             f"{100 * summary['difference_to_first'][name]:.1f} %")
    print(out_dir / "compare.png")
    print(out_dir / "compare.json")
    return 0


def _log_noise(result) -> None:
    if result.stopped_by != "photons":
        _log(f"stopped by {result.stopped_by.replace('_', ' ')} after {result.stats.photons:,} photons")
    if result.noise:
        worst = sorted(result.noise.items(), key=lambda kv: -kv[1])
        _log("relative noise: " + ", ".join(f"{name} {100 * v:.2g} %" for name, v in worst[:8]) +
             (f" (+{len(worst) - 8} more in report.json)" if len(worst) > 8 else ""))


def run_bake(args, bl_scene=None) -> int:
    """Bake with parsed `args`; `bl_scene` is the open Blender scene (None: open args.scene)."""
    settings = settings_from_args(args)
    blender, bl_scene, scene, out_dir, export_seconds = _open_scene(args, settings, bl_scene)
    result = _run_job(job_mod.Job(scene, settings, out_dir, export_seconds=export_seconds)).results[settings.estimator]
    _log_noise(result)
    if args.apply:
        blender.apply_all(bl_scene, result.files, args.uv_layer, settings.estimator)
    if args.save:
        blender.save_blend(Path(args.save).resolve(), result.files)
        print(f"detp_bake: saved {args.save}", file=sys.stderr)
    for name, files in result.files.items():
        for f in files:
            print(f)
    print(out_dir / "report.json")
    if args.save:
        print(Path(args.save).resolve())
    return 0


def main(argv: Optional[Sequence[str]] = None, bl_scene=None) -> int:
    parser = build_parser(with_scene_path=bl_scene is None)
    args = parser.parse_args(argv)
    try:
        if args.command == "bake":
            return run_bake(args, bl_scene)
        if args.command == "compare":
            return run_compare(args, bl_scene)
    except BakeError as exc:
        print(f"detp_bake: error: {exc}", file=sys.stderr)
        return 2
    except BakeCancelled:
        print("detp_bake: cancelled; nothing written", file=sys.stderr)
        return 130
    return 1
