"""Lightmap files through OpenImageIO: float EXR for the data, an sRGB PNG to look at.

Arrays here are (H, W, C) with row 0 at the bottom (v = 0), as the texels are laid out and as
Blender stores `Image.pixels`; files are written top row first, as every image viewer expects.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import BakeError


def _oiio():
    """OpenImageIO's module: Blender's own inside Blender (4.5 and later ship it; the extension does
    not bundle it), the pinned wheel outside it."""
    try:
        import OpenImageIO as oiio
    except ImportError as exc:
        raise BakeError("writing lightmaps needs OpenImageIO's Python module: Blender 4.5 and later "
                        "ship it; outside Blender, pip install OpenImageIO (requirements/)") from exc
    return oiio


def write_exr(path: str | os.PathLike, image: np.ndarray, half: bool = False, channels=None) -> None:
    """`channels`: the channels' names (a directional map's, lightmap/sh.py), else OIIO's R, G, B."""
    oiio = _oiio()
    data = np.ascontiguousarray(image[::-1], np.float32)
    h, w, c = data.shape
    spec = oiio.ImageSpec(w, h, c, "half" if half else "float")
    if channels is not None:
        spec.channelnames = tuple(channels)
    spec.attribute("compression", "zip")
    _write(oiio, path, spec, data)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """8-bit sRGB preview of linear values (1.0 = white), clipped."""
    oiio = _oiio()
    data = np.ascontiguousarray(np.round(linear_to_srgb(image[::-1]) * 255.0), np.uint8)
    h, w, c = data.shape
    _write(oiio, path, oiio.ImageSpec(w, h, c, "uint8"), data)


def _write(oiio, path, spec, data) -> None:
    path = str(path)
    spec.attribute("DateTime", "")  # no timestamp: the same bake gives byte-identical files
    out = oiio.ImageOutput.create(path)
    if out is None or not out.open(path, spec):
        raise BakeError(f"cannot write image '{path}': {oiio.geterror()}")
    try:
        if not out.write_image(data):
            raise BakeError(f"cannot write image '{path}': {out.geterror() or 'write failed (disk full?)'}")
    finally:
        closed = out.close()  # EXR data reaches the disk here: a full disk shows up now
    if not closed:
        raise BakeError(f"cannot write image '{path}': {out.geterror() or 'write failed (disk full?)'}")


def read_image(path: str | os.PathLike) -> np.ndarray:
    """(H, W, C) float32 with row 0 at the bottom: a written lightmap read back (tests, tools)."""
    oiio = _oiio()
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise BakeError(f"cannot read image '{path}': {oiio.geterror()}")
    try:
        data = inp.read_image("float")
    finally:
        inp.close()
    return np.ascontiguousarray(np.asarray(data, np.float32)[::-1])


WRITERS = {"exr": write_exr, "png": write_png}


_RESERVED = {"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(1, 10)), *(f"LPT{i}" for i in range(1, 10))}


def file_stem(name: str) -> str:
    """An object name made safe as a file name on every platform (Windows' reserved device names
    included: `CON` becomes `CON_`)."""
    bad = '<>:"/\\|?*'
    stem = "".join("_" if (ch in bad or ord(ch) < 32) else ch for ch in name).strip(" .")
    stem = stem or "object"
    if stem.split(".")[0].upper() in _RESERVED:
        stem = stem + "_"
    return stem


def file_stems(names) -> dict:
    """{name: stem} with every stem unique even on case-insensitive disks: names that would collide
    (`Wall/1` and `Wall_1`, `Box` and `box`) get `-2`, `-3`, … in the order given."""
    out, taken = {}, set()
    for name in names:
        stem = base = file_stem(name)
        k = 1
        while stem.lower() in taken:
            k += 1
            stem = f"{base}-{k}"
        taken.add(stem.lower())
        out[name] = stem
    return out


def check_writable_dir(path: str | os.PathLike) -> Path:
    """Create the output folder if needed and prove it is writable, before any long work (the
    bake's door, run/door.py, does it once)."""
    p = output_folder(path)
    try:
        probe = p / f".detp_bake_probe_{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise BakeError(f"output directory '{p}' is not writable: {exc.strerror or exc}") from None
    return p


def output_folder(path: str | os.PathLike) -> Path:
    """The output folder, created if needed, as an absolute path: images loaded from it keep pointing
    at it wherever the .blend is saved (Blender then stores them relative to the saved file)."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BakeError(f"output directory '{p}' is not writable: {exc.strerror or exc}") from None
    return p.resolve()
