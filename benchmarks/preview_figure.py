"""The live preview as a picture: the images a bake's Preview events carry (what the viewport shows
while the job runs), side by side for a few moments of a Cornell box bake, then the finished
lightmap (denoised).

    python benchmarks/preview_figure.py [--out benchmarks/figures/preview.png] [--photons N]

Each tile is the Floor, BackWall and TallBox lightmaps after so many photons, labelled with the
photon count and the noise the bake read off its batches at that moment.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402,F401  (puts the repository root on sys.path)

from detp_bake.run import comparison, job as job_mod
from detp_bake.lightmap import images  # noqa: E402
from detp_bake.run.bake import BakeSettings  # noqa: E402

OBJECTS = ("Floor", "BackWall", "TallBox")
TILE = 128


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=int, default=1_600_000)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "figures" / "preview.png"))
    args = ap.parse_args(argv)
    import bpy
    from detp_bake import blender
    bpy.ops.wm.open_mainfile(filepath=str(scenes.ROOT / "sample_scenes" / "cornell_box.blend"))
    scene = blender.export_scene(bpy.context.scene, None, None, None, 64, lambda m: None)
    settings = BakeSettings(photons=args.photons, resolution=64, batch_size=args.photons // 16)
    shots = {}
    for event in job_mod.Job(scene, settings, None, preview=1e-9).events():
        if isinstance(event, job_mod.Preview) and event.photons // settings.batch_size in (1, 2, 4, 16):
            shots[event.photons] = (event.images, event.noise)
        if isinstance(event, job_mod.Result):
            final = event.results[settings.estimator]
    shots["final"] = (final.images, max(final.noise.values()))
    scale = np.percentile(np.concatenate([final.images[o].ravel() for o in OBJECTS]), 99)
    columns = []
    for key, (imgs, noise) in shots.items():
        body = np.concatenate([comparison._fit(imgs[o][::-1] / scale, TILE) for o in OBJECTS], axis=0)
        text = "denoised" if key == "final" else f"{key / 1e6:.1f}M photons"
        if noise is not None:
            text += f"  {100 * noise:.1f} %"
        header = comparison._label(np.zeros((comparison.HEADER, TILE, 3)), text)
        columns.append(np.concatenate([header, body], axis=0))
        columns.append(np.full((columns[-1].shape[0], 4, 3), 0.3))
    picture = np.clip(np.concatenate(columns[:-1], axis=1), 0.0, 1.0)
    images.write_png(args.out, np.ascontiguousarray(picture[::-1], np.float32))
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
