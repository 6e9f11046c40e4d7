"""Chart-aware OIDN denoising of one baked lightmap.

A lightmap is mostly gutter: texels no UV chart covers, which hold 0 after a bake. Handed to a
denoiser as they are, those zeros are an edge the network preserves by darkening the chart texels
next to them, and the output would seam under bilinear filtering. So the gutter is filled first
(`dilation.dilate`, the extend-margin the bake gives its output images, then the covered mean for
whatever lies further out), the whole image is denoised, and afterwards only the covered texels are
kept and the gutter is filled again from the denoised ones.

OIDN runs on the CPU device through `pyoidn` (a cffi binding that ships the OIDN 2.5.1 libraries).
It is imported only when a denoise is asked for, so a bake without denoising never needs it.
Each lightmap gets its own filter, released when done, and none of OIDN's scratch stays after the
bake (pyoidn's one-call `denoise` keeps its filter and images until the next call). OIDN holds
about 555 bytes a pixel of scratch untiled, and its own tiling (maxMemoryMB) never brings that
under about 330 MB (measured at 768²-2048²: 370-420 MB at 2048²). So an image wider than TILE is
denoised here in tiles of at most TILE², each with TILE_OVERLAP texels of context on every side,
starting on multiples of TILE_ALIGN (the network pools by 2 four times: a tile off that grid sees
other pooling cells than the whole image, and its output moved by 0.2 % of the mean RMS), all at
the exposure OIDN would find for the whole image (`_exposure`, within 3e-6 of OIDN's own). The
output is then OIDN's on the whole image (1e-5 of the mean apart, tests/test_denoise.py), and
OIDN's scratch stays near 87 MB (2048²: 64 tiles of up to 464²; its plan is not a smooth curve:
at 448² it held 129 MB, at 432² 120), at the cost of the overlaps: 2.7 times the image's pixels
at 2048² (docs/real_levels.md).

Measured here (smooth point-light field over three charts, relative RMSE against the field, mean
of 3 seeds at 128², 1 seed at 512²): with white noise of 10 % / 20 %, RTLightmap gives
1.5 % / 3.3 % at 128² and 0.8 % / 1.6 % at 512²; RT with a white albedo guide 1.6 % / 3.1 % and
1.0 % / 2.3 %; plain RT without an albedo guide 2.4 % / 5.6 % at 128². Hence RTLightmap by
default, and RT always with an albedo guide. Noise correlated over the estimators' 1.5-texel
discs (a 3×3 box blur of white noise) passes through every variant almost untouched (10 % stays
9.8–10.0 %): the network takes it for signal, as on real bakes (docs/design.md, Denoising).

A bake with the texel histogram (white noise) denoises its direct and indirect parts apart and adds
them: alone, the smooth indirect part loses far more of its noise (tests/test_denoise.py; on the
L-shaped room 1.65 % RMSE against Cycles instead of 2.24 %, Cornell box 2.54 % against 2.99 %, at
1M photons). Disc estimates do better denoised together (2.42 % against 2.47 % on the L-room).

Limits: the constant extension flattens a gradient at a chart's edge, so border texels come out
~0.5–1 % low where irradiance rises towards the edge (10 % noise; unfilled, OIDN pulls them 5–7 %
towards a 0 gutter). Charts that lie a few texels apart in the atlas are still one image to OIDN;
charts under 8 texels wide are not denoised here at all but smoothed over the surface (fragments.py).
"""
from __future__ import annotations

from typing import Optional

import numba
import numpy as np


from ..components import label_boxes
from ..distance_transform import distance_transform
from ..errors import BakeError
from .dilation import dilate
from .texels import neighbour_pairs

FILTERS = ("RT", "RTLightmap")
# Rings of neighbour-mean extension before the rest of the gutter takes the covered mean. OIDN's
# network sees tens of texels around each output texel, but what it sees past a few rings of a
# smooth continuation hardly changes the chart's texels; a ring costs ~10 ms at 512² here.
FILL_RINGS = 16
MIN_REGION = 64  # texels: a region walled off from its neighbours is denoised only from this size
MAX_MEMORY_MB = 256  # OIDN's maxMemoryMB: more than a TILE² tile needs untiled (111 MB)
TILE = 464  # the widest image OIDN gets at once (module docstring)
# Up to WIDE_UNTIL pixels an image gets tiles of up to WIDE_TILE²: 2 × 2 tiles at 1024² hand OIDN
# 1.5 times the image's pixels where 464² tiles hand it 2.6 times (4 × 4), and its scratch (about
# 290 MB) is what a 1024² bake can spare; larger images keep TILE, their memory bound.
WIDE_TILE = 720
WIDE_UNTIL = 1024 * 1024
TILE_OVERLAP = 96  # context on each side of a tile, a multiple of TILE_ALIGN (module docstring)
TILE_ALIGN = 16  # OIDN's network pools by 2 four times: tiles start on its 16-texel grid
LUMA = np.array([0.212671, 0.715160, 0.072169], np.float32)  # OIDN's luminance weights (autoexposure)
QUALITY = {"high": 6, "balanced": 5, "fast": 4}  # OIDN_QUALITY_*


def _pyoidn():
    """Import pyoidn or say which package is missing (it is optional until a denoise is asked)."""
    try:
        import pyoidn
    except ImportError as exc:
        raise BakeError("denoising needs the Python package 'pyoidn' "
                        f"(pip install pyoidn==2.5.1.0); it could not be imported: {exc}") from exc
    return pyoidn


def available() -> bool:
    """Whether pyoidn can be imported here (for a UI that greys out its denoise option)."""
    try:
        _pyoidn()
    except BakeError:
        return False
    return True


def _grow(mask: np.ndarray, rings: int) -> np.ndarray:
    """The texels `dilation.dilate` reaches in `rings` rings (8-neighbour growth), as a bool mask."""
    grown = mask.copy()
    for _ in range(int(rings)):
        p = np.pad(grown, 1)
        nxt = p[:-2, 1:-1] | p[2:, 1:-1] | p[1:-1, :-2] | p[1:-1, 2:]
        nxt |= p[:-2, :-2] | p[:-2, 2:] | p[2:, :-2] | p[2:, 2:] | grown
        if (nxt == grown).all():
            break
        grown = nxt
    return grown


def fill_gutter(image: np.ndarray, mask: np.ndarray, rings: int = FILL_RINGS, in_place: bool = False) -> np.ndarray:
    """Every texel of `image` given a value that continues the covered ones smoothly: `rings` of
    neighbour-mean extension (`dilation.dilate`), then the mean of the covered texels beyond, so no
    texel the denoiser sees is an artificial 0 (or garbage from an earlier pass). `in_place`: fill
    `image` itself (float32) rather than a copy."""
    out = dilate(image, mask, rings, in_place=in_place)
    reached = _grow(mask, rings)
    if not reached.all():
        out[~reached] = image[mask].mean(axis=0, dtype=np.float64) if mask.any() else 0.0
    return out


def _covered(name: str, a: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A copy of `a` with its covered texels and 0 in the gutter: only covered texels are read, so
    whatever the gutter held (0, an earlier dilation, NaN) cannot leak into the fill."""
    return _zero_gutter(name, np.array(a), mask)


def _check_guide(name: str, guide: Optional[np.ndarray], shape: tuple) -> Optional[np.ndarray]:
    if guide is None:
        return None
    guide = np.asarray(guide, dtype=np.float32)
    if guide.shape != shape:
        raise BakeError(f"denoise: {name} guide has shape {guide.shape}, the lightmap {shape}")
    return guide


def denoise_lightmap(image: np.ndarray, mask: np.ndarray, albedo: Optional[np.ndarray] = None,
                     normal: Optional[np.ndarray] = None, filter: Optional[str] = None,
                     keep_energy: bool = True, margin: int = 16, quality: str = "high",
                     weights: Optional[np.ndarray] = None, regions: Optional[np.ndarray] = None,
                     fragments=None, apart: int = 1, own: bool = False) -> np.ndarray:
    """Denoise one lightmap and return a new (H, W, 3) float32 image in the same layout.

    image: (H, W, 3) irradiance E/π (HDR, ≥ 0), row 0 at the bottom as in texels.py; only the
    texels where `mask` (H, W) bool is True (covered by a UV chart) are read.
    albedo, normal: optional (H, W, 3) texel-space guides for the RT filter (albedo in [0, 1],
    normal any length, both noise-free); covered texels are read, the gutter is filled like the
    image's. RT always gets an albedo guide, white when none is given: E/π is the radiance of a
    white Lambertian surface, so white is the albedo that matches the image (a material's albedo
    only adds edges that irradiance does not have), and OIDN takes normals only beside an albedo.
    filter: "RTLightmap" (OIDN's filter trained on lightmaps; no guides) or "RT" (its HDR filter
    for renders). None picks RTLightmap, or RT when a guide is given (module docstring: why).
    keep_energy: rescale each channel so the mean over covered texels equals the raw mean. OIDN
    moves that mean by up to ~0.6 % (measured at 40 % noise with guides; ~0.1 % at 10 %), while
    the raw mean is what the photons measured; one factor per channel leaves the shape as is.
    weights: (H, W) surface area per texel, for that mean (or a callable that makes it: with `own`
    and one OIDN run, it is made before and after OIDN's run rather than kept through it). A
    chart's border texels cover slivers of surface, and OIDN evens them out with their neighbours:
    a plain mean over texels then counts a small chart's (a leaf's) rim as much as its middle, and
    the rescale shifts its energy.
    margin: rings of `dilation.dilate` that refill the gutter from the denoised texels afterwards
    (pass the bake's margin setting); texels further out are 0, as a bake leaves them.
    quality: OIDN's "high" (default), "balanced" or "fast".
    regions: (H, W) int labels of texels that see each other along the surface (validity.regions):
    no light crosses from one region to a neighbouring one, as regions that touch are denoised in
    different runs (`region_runs`), every texel outside a run being gutter to it.
    fragments: the texels of charts too narrow for OIDN and their neighbours on the surface
    (fragments.Fragments): they are gutter to every OIDN run, and take their neighbours' mean.
    apart: regions within this many texels are denoised in different runs (`region_runs`).
    own: `image` is the caller's to lose (a float32 temporary of the bake): when one OIDN run covers
    the lightmap, the denoiser works in it and returns OIDN's output image as the result, instead
    of two more copies of the image (at 2048² each is 50 MB).

    Raises BakeError for a bad shape or filter, NaN/inf in covered texels, a missing pyoidn, or
    an OIDN failure.
    """
    image, mask, albedo, normal, filter = _checked(image, mask, albedo, normal, filter, quality,
                                                   None if callable(weights) else weights, regions)
    if _all_black(image, mask):  # a part no light reached (a sun-lit crate's soft direct light): 0
        return np.zeros_like(image)
    runs_mask, smoothed = mask, None
    if fragments is not None and len(fragments):
        runs_mask = mask.copy()
        runs_mask.flat[fragments.pixel] = False
        covered = _covered("lightmap", image, mask)
        np.maximum(covered, 0.0, out=covered)
        smoothed = fragments.smooth(covered)
        del covered
    runs = region_runs(regions, runs_mask, apart)
    if own and len(runs) == 1 and runs[0][2]:  # one OIDN run over the whole image, in `image` itself
        result = _denoise_part(image, runs[0][1], albedo, normal, filter, keep_energy, QUALITY[quality], weights,
                               own=True)  # a callable `weights` is made there, twice, around OIDN's run
    else:
        weights = weights() if callable(weights) else weights
        result = np.zeros_like(image)
        for box, part, network in runs:
            pick = lambda a: None if a is None else a[box]  # noqa: E731
            if network:
                result[box][part] = _denoise_part(image[box], part, pick(albedo), pick(normal), filter, keep_energy,
                                                  QUALITY[quality], pick(weights))
            else:
                w = None if weights is None or not weights[box][part].sum() > 0 else weights[box][part]
                result[box][part] = np.average(np.maximum(image[box][part], 0.0), axis=0, weights=w)
    if smoothed is not None:
        result.reshape(-1, 3)[fragments.pixel] = smoothed
    return dilate(result, mask, margin, in_place=True)


@numba.njit(cache=True)
def _all_black(img, mask):
    """Whether no texel under `mask` holds a positive value (nor NaN: that is refused later)."""
    h, w, channels = img.shape
    for y in range(h):
        for x in range(w):
            if mask[y, x]:
                for c in range(channels):
                    if not img[y, x, c] <= 0.0:
                        return False
    return True


def _checked(image, mask, albedo, normal, filter, quality, weights, regions) -> tuple:
    """denoise_lightmap's inputs as arrays of the right kinds, its filter chosen; a BakeError
    for a bad shape, filter or quality."""
    image = np.asarray(image, dtype=np.float32)
    mask = np.asarray(mask, dtype=bool)
    if image.ndim != 3 or image.shape[2] != 3:
        raise BakeError(f"denoise: lightmap must be (H, W, 3), got {image.shape}")
    if mask.shape != image.shape[:2]:
        raise BakeError(f"denoise: mask has shape {mask.shape}, the lightmap {image.shape[:2]}")
    for name, extra in (("weights", weights), ("regions", regions)):
        if extra is not None and np.shape(extra) != mask.shape:
            raise BakeError(f"denoise: {name} have shape {np.shape(extra)}, the lightmap {image.shape[:2]}")
    albedo = _check_guide("albedo", albedo, image.shape)
    normal = _check_guide("normal", normal, image.shape)
    if filter is None:
        filter = "RT" if albedo is not None or normal is not None else "RTLightmap"
    if filter not in FILTERS:
        raise BakeError(f"denoise: unknown filter {filter!r} (choose from {', '.join(FILTERS)})")
    if filter == "RTLightmap" and (albedo is not None or normal is not None):
        raise BakeError("denoise: the RTLightmap filter takes no albedo or normal guide; use RT")
    if quality not in QUALITY:
        raise BakeError(f"denoise: unknown quality {quality!r} (choose from {', '.join(QUALITY)})")
    return image, mask, albedo, normal, filter


def _touching(label: np.ndarray, count: int, reach: int) -> np.ndarray:
    """Sorted codes a·count + b of labels a ≠ b that lie within `reach` texels of each other (1:
    8-neighbours): each gutter texel within reach/2 takes its nearest covered texel's label."""
    if reach > 1:
        far, (rows, cols) = distance_transform(label < 0)
        label = np.where(far <= 0.5 * reach + 0.5, label[rows, cols], -1)
    touch = np.zeros(0, np.int64)
    for a, b in neighbour_pairs(label):
        differ = (a >= 0) & (b >= 0) & (a != b)
        touch = np.concatenate([touch, a[differ] * count + b[differ], b[differ] * count + a[differ]])
    return np.unique(touch)


def region_runs(regions: Optional[np.ndarray], mask: np.ndarray, reach: int = 1) -> list:
    """[(box, texels, denoise)]: how one lightmap is denoised, as runs over the (H, W) image's
    slices `box` (row slice, column slice), each on the texels of its mask `texels` (the box's
    shape) with OIDN (`denoise`) or as their mean. Without regions, one OIDN run over the whole
    image. With regions: one OIDN run over the whole image for the largest regions and every region
    that touches none of them (greedily, largest first), then each other region apart, in the box
    of its texels and FILL_RINGS round them; a region of fewer than MIN_REGION texels (a sliver by a
    wall) is too small for the network to see anything in, and takes its mean. Regions touch when
    they are 8-neighbours, or with `reach` when they lie within that many texels (an atlas's
    objects: their charts lie a padding apart, and none may take another's light)."""
    whole = (slice(0, mask.shape[0]), slice(0, mask.shape[1]))
    if regions is None or not mask.any():
        return [(whole, mask, True)]
    label = np.where(mask, regions, -1).astype(np.int64)
    count = int(label.max()) + 1
    if count <= 1:
        return [(whole, mask, True)]
    touch = _touching(label, count, reach)
    near = np.split(touch % count, np.searchsorted(touch // count, np.arange(1, count)))
    size = np.bincount(label[label >= 0], minlength=count)
    first = np.zeros(count, bool)
    taken = np.zeros(count, bool)  # in the first run, or touching it
    for r in np.argsort(-size, kind="stable"):
        if not taken[r]:
            first[r] = taken[r] = True
            taken[near[r]] = True
    runs = [(whole, mask & first[np.maximum(label, 0)], True)]
    h, w = mask.shape
    for r, found in enumerate(label_boxes(label)):
        if first[r] or found is None:  # None: a region none of whose texels is in `mask`
            continue
        rows, cols = found
        if size[r] >= MIN_REGION:
            rows = slice(max(rows.start - FILL_RINGS, 0), min(rows.stop + FILL_RINGS, h))
            cols = slice(max(cols.start - FILL_RINGS, 0), min(cols.stop + FILL_RINGS, w))
        runs.append(((rows, cols), label[rows, cols] == r, size[r] >= MIN_REGION))
    return runs


def _zero_gutter(name: str, a: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """`_covered` in `a` itself: its gutter set to 0 (NaN or inf in covered texels refused)."""
    bad = ~np.isfinite(a)
    bad[~mask] = False
    if bad.any():
        raise BakeError(f"denoise: the {name} holds NaN or infinite values in covered texels")
    del bad
    a[~mask] = 0.0
    return a


@numba.njit(cache=True)
def _masked_mean(img, mask, weights, weighted):
    """The mean of `img`'s texels under `mask` per channel, in float64, weighted by `weights`
    when `weighted` and their sum is positive (else the plain mean): no copy of the texels, nor
    of their products."""
    h, w, channels = img.shape
    total = np.zeros(channels)
    plain = np.zeros(channels)
    wsum = 0.0
    count = 0
    for y in range(h):
        for x in range(w):
            if mask[y, x]:
                k = np.float64(weights[y, x]) if weighted else 1.0
                wsum += k
                count += 1
                for c in range(channels):
                    total[c] += k * np.float64(img[y, x, c])
                    plain[c] += np.float64(img[y, x, c])
    if weighted and wsum > 0.0:
        return total / wsum
    return plain / max(count, 1)


@numba.njit(cache=True)
def _rescale(img, mask, scale, apply):
    """In place: texels outside `mask` 0, those under it clamped at 0 and, when `apply`, times
    `scale` per channel (in float64, rounded once to float32). False if a texel is not finite."""
    h, w, channels = img.shape
    for y in range(h):
        for x in range(w):
            for c in range(channels):
                if not mask[y, x]:
                    img[y, x, c] = 0.0
                    continue
                v = img[y, x, c]
                if not np.isfinite(v):
                    return False
                v = max(v, np.float32(0.0))
                img[y, x, c] = np.float32(np.float64(v) * scale[c]) if apply else v
    return True


def _denoise_part(image, mask, albedo, normal, filter, keep_energy, quality, weights, own=False) -> np.ndarray:
    """The denoised values of the texels of `mask` ((K, 3) float32, in mask order), every other
    texel taken for gutter. `own` (denoise_lightmap): work in `image` and return the whole image,
    the texels of `mask` denoised and 0 elsewhere. Means are taken in compiled passes: at 2048²
    a copy of the texels and their float64 products would be 60 bytes a texel more."""
    # Irradiance is never negative; OIDN's HDR mode assumes so. Buffers are reused in place
    # (the same numbers): at 2048² each (H, W, 3) copy is 50 MB.
    src = _zero_gutter("lightmap", image, mask) if own else _covered("lightmap", image, mask)
    np.maximum(src, 0.0, out=src)
    if not src.any():  # all black stays black: OIDN returns up to 0.03 for an all-0 input
        return src if own else np.zeros((int(mask.sum()), 3), np.float32)
    area = lambda: np.zeros((1, 1), np.float32) if weights is None else np.asarray(  # noqa: E731
        weights() if callable(weights) else weights, np.float32)
    raw_mean = _masked_mean(src, mask, area(), weights is not None) if keep_energy else None

    color = fill_gutter(src, mask, in_place=True)
    del src
    kwargs = {}
    if filter == "RT":
        alb = (np.ones_like(image) if albedo is None
               else np.clip(fill_gutter(_covered("albedo guide", albedo, mask), mask), 0.0, 1.0))
        kwargs = {"hdr": True, "clean_aux": True,  # guides come from geometry: no noise in them
                  "albedo": alb}
        if normal is not None:
            kwargs["normal"] = fill_gutter(_covered("normal guide", normal, mask), mask)
    try:
        result = _run_filter(color, filter, quality, need=mask, **kwargs)
    except (RuntimeError, ValueError, TypeError, OSError) as exc:  # OSError: OIDN's .so loads now
        raise BakeError(f"denoise: OIDN failed on a {image.shape[1]}x{image.shape[0]} lightmap "
                        f"({filter}): {exc}") from exc
    del color, kwargs, image
    if not _rescale(result, mask, np.ones(3), False):  # clamped at 0, gutter 0
        raise BakeError(f"denoise: OIDN returned non-finite texels ({filter})")
    if keep_energy:
        den_mean = _masked_mean(result, mask, area(), weights is not None)
        scale = np.where(den_mean > 0, raw_mean / np.where(den_mean > 0, den_mean, 1.0), 1.0)
        _rescale(result, mask, scale, True)
    return result if own else result[mask]


_device = None


def _device_once():
    """OIDN's CPU device, made once (bakes run one at a time: job.py)."""
    global _device
    pyoidn = _pyoidn()
    if _device is None:
        device = pyoidn.Device()
        device.commit()
        _device = device
        _check("device")
    return _device


def _check(what: str) -> None:
    err = _device.get_error()
    if err:
        raise RuntimeError(f"{what}: {err}")


def _exposure(color: np.ndarray) -> float:
    """The input scale OIDN's autoexposure finds for the whole image: 0.18 over the geometric mean
    of the luminance of 16×16 blocks (blocks of mean luminance above 1e-8). Tiles denoised apart
    all get it, so each sees the exposure the whole image would have had."""
    h, w = color.shape[:2]
    rows = np.arange(-(-h // 16)) * h // -(-h // 16)
    cols = np.arange(-(-w // 16)) * w // -(-w // 16)
    lum = np.add.reduceat(color @ LUMA, rows, axis=0, dtype=np.float64)
    lum = np.add.reduceat(lum, cols, axis=1) / np.outer(np.diff(rows, append=h), np.diff(cols, append=w))
    bright = lum[lum > 1e-8]
    return float(0.18 / np.exp2(np.log2(bright).mean())) if bright.size else 1.0


def tile_for(pixels: int) -> int:
    """The widest tile OIDN gets of an image of `pixels` pixels (WIDE_TILE, TILE)."""
    return max(WIDE_TILE, TILE) if pixels <= WIDE_UNTIL else TILE


def _spans(n: int, tile: int = 0) -> list:
    """[(start, stop)] cores of one axis, each `tile` (TILE) less its overlaps wide (the last one
    less), starting on multiples of TILE_ALIGN: a tile's pooling grid is then the whole image's."""
    core = ((tile or TILE) - 2 * TILE_OVERLAP) // TILE_ALIGN * TILE_ALIGN
    return [(a, min(a + core, n)) for a in range(0, n, core)]


def _run_filter(color: np.ndarray, filter: str, quality: int, hdr: bool = False, clean_aux: bool = False,
                albedo: Optional[np.ndarray] = None, normal: Optional[np.ndarray] = None,
                need: Optional[np.ndarray] = None) -> np.ndarray:
    """OIDN on one image, in tiles when it is wider than `tile_for` its pixels (module docstring),
    through one filter released on return. A tiled image is denoised over `color` itself (a float32
    scratch image, every caller's): a band of tiles is written back once the band below it, whose
    tiles read TILE_OVERLAP rows into it, is done (every core is wider than the overlap), so no
    second full-size image is made. `need`: (H, W) bool, the texels whose output is read; a tile
    whose core holds none of them is not run (its core keeps `color`'s values)."""
    pyoidn = _pyoidn()
    device = _device_once()
    guides = {name: img for name, img in (("albedo", albedo), ("normal", normal)) if img is not None}
    h, w = color.shape[:2]
    flt = pyoidn.Filter(device, filter)
    try:
        _check("filter")
        if filter == "RT":
            flt.set_bool("hdr", hdr)
            flt.set_bool("cleanAux", clean_aux)
        flt.set_int("quality", quality)
        flt.set_int("maxMemoryMB", MAX_MEMORY_MB)
        widest = tile_for(h * w)
        if h <= widest and w <= widest:
            return _execute(flt, pyoidn, color, guides)
        flt.set_float("inputScale", _exposure(color))
        done = None  # the last band of tiles, written over `color` once the next band has read it
        for r0, r1 in _spans(h, widest):
            rows = slice(max(r0 - TILE_OVERLAP, 0), min(r1 + TILE_OVERLAP, h))
            band = np.array(color[r0:r1])
            for c0, c1 in _spans(w, widest):
                if need is not None and not need[r0:r1, c0:c1].any():
                    continue
                cols = slice(max(c0 - TILE_OVERLAP, 0), min(c1 + TILE_OVERLAP, w))
                tile = _execute(flt, pyoidn, color[rows, cols], {k: g[rows, cols] for k, g in guides.items()})
                band[:, c0:c1] = tile[r0 - rows.start:r1 - rows.start, c0 - cols.start:c1 - cols.start]
            if done is not None:
                color[done[0]:done[0] + len(done[1])] = done[1]
            done = (r0, band)
        color[done[0]:] = done[1]
        return color
    finally:
        flt.release()


def _execute(flt, pyoidn, color: np.ndarray, guides: dict) -> np.ndarray:
    """One execution of `flt` on `color` (and its guides) into a new image."""
    images = {"color": np.ascontiguousarray(color, np.float32)}
    images.update((name, np.ascontiguousarray(img, np.float32)) for name, img in guides.items())
    images["output"] = out = np.empty_like(images["color"])
    for name, img in images.items():
        flt.set_image(name, img, pyoidn.OIDN_FORMAT_FLOAT3)
    flt.commit()
    _check("commit")
    flt.execute()
    _check("execute")
    return out
