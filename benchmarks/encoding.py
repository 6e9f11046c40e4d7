"""How far each 8- or 16-bit image form of a lightmap is from the baked EXR: the RGBE the glTF export
writes (detp_bake/lightmap/encoding.py), RGBM with ranges 8 and 16, 16-bit linear PNG under one
exposure, and 8-bit sRGB under one exposure (kept as the material's lightmap intensity).

    python benchmarks/encoding.py [--scenes cornell_box,courtyard] [--resolution 128] [--json OUT]

Bakes each sample scene with the command line (defaults: texel histogram, denoised), then reads
every lightmap. Error (`encoding.lit_error`): over the texels whose brightest channel is above 1 %
of the lightmap's brightest, the mean and the largest absolute error of a channel, as a share of
the mean channel value there; the table gives the worst lightmap of each scene. `rgbe, filtered`
is RGBE sampled by a GPU's bilinear filter halfway between horizontal neighbours (bytes blended,
then decoded), against the blend of the EXR's texels: what a viewer gets when it filters before
decoding. Writes JSON (default benchmarks/results/encoding.json).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from detp_bake.lightmap import encoding, images  # noqa: E402

FORMS = {
    "rgbe": lambda x: encoding.rgbe_decode(encoding.rgbe_encode(x)),
    "rgbm 8": lambda x: encoding.rgbm_roundtrip(x, 8.0),
    "rgbm 16": lambda x: encoding.rgbm_roundtrip(x, 16.0),
    "png16 linear": encoding.linear16_roundtrip,
    "srgb8 + intensity": encoding.srgb8_roundtrip,
}


def filtered_rgbe(x: np.ndarray) -> tuple:
    """(decoded blend of the RGBE bytes, blend of the floats) halfway between horizontal neighbours."""
    q = encoding.rgbe_encode(x).astype(np.float64)
    mid = np.rint((q[:, 1:] + q[:, :-1]) / 2)  # an 8-bit filter's result, rounded
    decoded = mid[..., :3] * np.ldexp(1.0, mid[..., 3].astype(int) - 136)[..., None]
    return np.where(mid[..., 3:] < 1, 0.0, decoded), (x[:, 1:] + x[:, :-1]) / 2


def bake(scene: str, out: Path, resolution: int) -> dict:
    """{object: EXR path} of a default bake of a sample scene."""
    cmd = [sys.executable, "-m", "detp_bake", "bake", str(ROOT / "sample_scenes" / f"{scene}.blend"),
           "--out", str(out), "--resolution", str(resolution), "--json"]
    proc = subprocess.run(cmd, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True,
                          text=True)
    if proc.returncode != 0:
        sys.exit(f"bake of {scene} failed:\n{proc.stderr[-3000:]}")
    files = json.loads(proc.stdout)["files"]
    return {name: next(p for p in paths if p.endswith(".exr")) for name, paths in files.items()}


def measure(exrs: dict) -> dict:
    """{form: {object: lit_error}} for every lightmap."""
    table = {form: {} for form in [*FORMS, "rgbe, filtered"]}
    for name, path in exrs.items():
        x = images.read_image(path)[..., :3].astype(np.float64)
        for form, roundtrip in FORMS.items():
            table[form][name] = encoding.lit_error(x, roundtrip(x))
        got, want = filtered_rgbe(x)
        table["rgbe, filtered"][name] = encoding.lit_error(want, got)
    return table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="cornell_box,courtyard")
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "encoding.json"))
    args = ap.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in args.scenes.split(","):
            exrs = bake(scene, Path(tmp) / scene, args.resolution)
            results[scene] = measure(exrs)
    print(f"{'form':<20}" + "".join(f"{s + ' mean':>22}{s + ' max':>20}" for s in results))
    for form in next(iter(results.values())):
        row = f"{form:<20}"
        for scene, table in results.items():
            worst = max(table[form].values(), key=lambda e: e["mean"])
            row += f"{100 * worst['mean']:>21.3f}%{100 * max(e['max'] for e in table[form].values()):>19.2f}%"
        print(row)
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps({"resolution": args.resolution, "lit_share": encoding.LIT,
                                           "scenes": results}, indent=1, allow_nan=False))
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
