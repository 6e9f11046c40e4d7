"""The bytes a bake writes, as fingerprints: every estimator on the sample scenes, one seed, so a
change meant to keep behaviour (a refactor, a regrouping) can show that it did.

    python benchmarks/fingerprint.py --out FILE        # record
    python benchmarks/fingerprint.py --check FILE      # bake again and compare; exit 1 on a change

Each bake is small (64² per object, 200k photons, sites off) and runs the whole pipeline: export,
texels and validity, direct light, tracing, the estimator, denoising and dilation. `detp` (brute
force) bakes the Cornell box at 16², `hybrid` a frame range of the quasi-static room (frames 1-2,
written and read back). The fingerprint of a lightmap is the SHA-256 of its float32 image. About a
minute on 2 cores.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402  (puts the repository root on sys.path)

from detp_bake import estimators  # noqa: E402
from detp_bake.lightmap import images  # noqa: E402
from detp_bake.run import frames  # noqa: E402
from detp_bake.run.bake import BakeSettings, compute_many  # noqa: E402

SCENES = ("cornell_box", "l_room", "window_room", "courtyard")


def _digest(img) -> str:
    return hashlib.sha256(img.astype("float32").tobytes()).hexdigest()


def _hybrid_range(out: dict) -> None:
    """frames 1-2 of the quasi-static room with the hybrid, written and read back."""
    import tempfile
    import bpy
    from detp_bake import blender
    scenes.blend_scene("quasi_static", 32)
    scene_at = blender.frame_exporter(bpy.context.scene, None, None, 32, lambda m: None)
    with tempfile.TemporaryDirectory() as tmp:
        done = frames.bake_frames(scene_at, frames.parse_frames("1-2"),
                                  BakeSettings(estimator="hybrid", photons=100_000, seed=3, resolution=32), tmp)
        for frame, files in done.files.items():
            for obj, paths in sorted(files.items()):
                exr = next(p for p in paths if p.endswith(".exr"))
                out[f"quasi_static/{obj}/hybrid/{frame}"] = _digest(images.read_image(exr))


def fingerprints() -> dict:
    out = {}
    names = [n for n in estimators.names() if n not in ("detp", "hybrid")]  # detp: slow; hybrid: frame ranges
    for name in SCENES:
        scene = scenes.blend_scene(name, 64)
        results = compute_many(scene, BakeSettings(photons=200_000, seed=3, resolution=64, indirect_spacing=1), names)
        for est, r in results.items():
            for obj, img in sorted(r.images.items()):
                out[f"{name}/{obj}/{est}"] = _digest(img)
    detp = compute_many(scenes.blend_scene("cornell_box", 16), BakeSettings(photons=20_000, seed=3, resolution=16),
                        ["detp"])["detp"]
    for obj, img in sorted(detp.images.items()):
        out[f"cornell_box/{obj}/detp"] = _digest(img)
    _hybrid_range(out)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    group = ap.add_mutually_exclusive_group(required=True)
    group.add_argument("--out", type=Path, help="write the fingerprints here")
    group.add_argument("--check", type=Path, help="compare with the fingerprints written here earlier")
    args = ap.parse_args(argv)
    with scenes.quiet_stdout():
        now = fingerprints()
    if args.out:
        args.out.write_text(json.dumps(now, indent=1, sort_keys=True, allow_nan=False))
        print(f"{len(now)} lightmaps fingerprinted into {args.out}")
        return 0
    before = json.loads(args.check.read_text())
    changed = sorted(k for k in before.keys() | now.keys() if before.get(k) != now.get(k))
    for key in changed:
        print(f"changed: {key}")
    print(f"{len(now) - len(changed)} of {len(now)} lightmaps the same, byte for byte")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
