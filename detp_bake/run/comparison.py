"""Estimators side by side: a labelled grid of each estimator's lightmaps and a heat map of its
difference to the first, as one image (no Blender needed)."""
from __future__ import annotations

import numpy as np

from ..lightmap import images

HEADER = 22  # pixels of label strip above each row


def _fit(img: np.ndarray, size: int) -> np.ndarray:
    """Nearest-neighbour resize of an (H, W, C) image to size × size."""
    h, w = img.shape[:2]
    rows = (np.arange(size) * h // size).clip(0, h - 1)
    cols = (np.arange(size) * w // size).clip(0, w - 1)
    return img[rows][:, cols]


def heat(x: np.ndarray) -> np.ndarray:
    """0 → black, 0.25 → red, 0.5 and above → yellow."""
    t = np.clip(x / 0.5, 0.0, 1.0)
    return np.stack([np.clip(2 * t, 0, 1), np.clip(2 * t - 1, 0, 1), np.zeros_like(t)], axis=-1)


def relative_difference(a: dict, b: dict, masks: dict) -> float:
    """RMS difference of lightmaps `a` from `b` over covered texels, relative to b's mean."""
    da = np.concatenate([a[n][masks[n]] for n in masks])
    db = np.concatenate([b[n][masks[n]] for n in masks])
    return float(np.sqrt(np.mean((da - db) ** 2)) / max(float(np.mean(db)), 1e-30))


def comparison_image(lightmaps: dict, masks: dict, seconds: dict, tile: int = 128):
    """lightmaps: {estimator: {object: (H, W, 3) E/π, row 0 at the bottom}}, first = reference.
    Returns (image (H, W, 3) in [0, 1], row 0 at the bottom, for an sRGB PNG; {estimator: rel diff})."""
    names = list(lightmaps)
    objects = list(masks)
    ref = lightmaps[names[0]]
    scale = np.percentile(np.concatenate([ref[o][masks[o]].ravel() for o in objects]), 99) or 1.0
    rows, diffs = [], {}
    for name in names:
        maps = lightmaps[name]
        diffs[name] = relative_difference(maps, ref, masks)
        left = np.concatenate([_fit(maps[o][::-1] / scale, tile) for o in objects], axis=1)
        err = [np.abs(maps[o] - ref[o]).mean(axis=-1) / (scale / 2) * masks[o] for o in objects]
        right = np.concatenate([_fit(heat(e)[::-1], tile) for e in err], axis=1)
        body = np.concatenate([left, np.full((tile, 4, 3), 0.3), right], axis=1)
        header = np.zeros((HEADER, body.shape[1], 3))
        label = f"{name}   {seconds.get(name, 0.0):.2f} s   diff to {names[0]}: {100 * diffs[name]:.1f} %"
        rows.append(np.concatenate([_label(header, label), body], axis=0))
    image = np.clip(np.concatenate(rows, axis=0), 0.0, 1.0)
    return np.ascontiguousarray(image[::-1], np.float32), diffs


def _label(strip: np.ndarray, text: str) -> np.ndarray:
    try:
        import OpenImageIO as oiio
    except ImportError:  # the grid is still useful without its labels
        return strip
    h, w = strip.shape[:2]
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 3, "float"))
    oiio.ImageBufAlgo.render_text(buf, 4, h - 6, text, 14, "", (1.0, 1.0, 1.0))
    return np.asarray(buf.get_pixels(oiio.FLOAT), np.float32).reshape(h, w, 3)


SUMMARY = ("estimators", "reference", "photons", "trace_seconds", "seconds", "difference_to_first")


def report_files(results: dict, names: list) -> tuple[dict, dict]:
    """One report for a comparison, what every front end writes (bake.write_many stages it with
    the lightmaps, all or nothing): compare.png (the grid) and compare.json, with the shared
    photons once and a section per estimator (its settings, counters, noise, seconds and files,
    as its own report.json has them, plus its difference to the reference, the first of `names`).
    Returns (the summary, {file name: write(path)})."""
    import json

    first = results[names[0]]
    seconds = {n: results[n].seconds["estimate"] for n in names}
    picture, diffs = comparison_image({n: results[n].images for n in names}, first.masks, seconds)
    summary = {"estimators": list(names), "reference": names[0], "photons": first.stats.photons,
               "trace_seconds": first.seconds["trace"], "seconds": seconds, "difference_to_first": diffs}

    def compare_json(path):
        sections = {}
        for name in names:  # read when staged: the lightmaps' paths are known by then
            section = results[name].report()
            section["difference_to_reference"] = diffs[name]
            sections[name] = section
        path.write_text(json.dumps({**summary, "files": {n: results[n].files for n in names},
                                    "image": "compare.png", "sections": sections}, indent=2, allow_nan=False))

    return summary, {"compare.png": lambda path: images.write_png(path, picture), "compare.json": compare_json}
