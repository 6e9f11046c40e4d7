"""The tangent discs of the DETP family and the one rule that decides whether a segment crosses one.

Segment (o, w, L) crosses the disc of texel (x, n, r) when it arrives from the front (w·n < 0) and
  (a) its plane hit t* = ((x − o)·n)/(w·n) lies in (0, L + ε] within r of x, or
  (b) it ends short of the plane but inside the slab 0 ≤ (e − x)·n ≤ δ above the disc, its end e
      within r of x laterally.
(a) is the rule of docs/design.md (Estimators); ε absorbs float error for segments ending on the disc's own plane. (b)
keeps concave surfaces honest: on a surface of radius R, a photon landing ρ from x ends ρ²/(2R)
before the tangent plane, so (b) with δ = r/4 counts every landing within the disc on any surface
with R ≥ 2r. The bake narrows δ to what the texel's own surface needs (rise.py: its greatest height
in front of the tangent plane within r, plus r/50), so a disc on a leaf does not count the photons
that landed on another leaf lying just in front of it. Both parts are local to a cylinder of radius r and height δ over the disc, so every
accelerated search bounds that cylinder, and all three estimators find exactly the same crossings.

Weights: constant 1/(πr²), or Epanechnikov 2(1 − d²/r²)/(πr²); both integrate to 1 over the disc.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..errors import BakeError
from ..lightmap.texels import TexelSet

SLAB = 0.25  # δ as a fraction of r, at most
FLAT_SLAB = 0.02  # δ over the texel's own surface rise, as a fraction of r
RISE_STEP = 0.01  # the rise is rounded up to steps of this fraction of r
CLEARANCE_FLOOR = 0.25  # clearance cuts a disc to no less than this fraction of its radius
# ... or of this one where something stands on the texel's square (a wall: validity.py), so that its
# disc does not reach through to the far side
CUT_FLOOR = 0.02
KERNELS = {"constant": 0, "epanechnikov": 1}


@dataclass
class Discs:
    centre: np.ndarray  # (N, 3) float64
    normal: np.ndarray  # (N, 3) float64
    radius: np.ndarray  # (N,) float64
    slab: np.ndarray  # (N,) float64, δ
    eps: float  # ε, absolute
    kernel: int

    def __len__(self):
        return len(self.radius)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned boxes around each disc's cylinder (disc plus slab), padded by ε."""
        n = self.normal
        half = self.radius[:, None] * np.sqrt(np.clip(1.0 - n * n, 0.0, 1.0))
        top = self.centre + n * self.slab[:, None]
        lo = np.minimum(self.centre, top) - half - self.eps
        hi = np.maximum(self.centre, top) + half + self.eps
        return lo, hi

    def bounding_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre and radius of a sphere around each disc's cylinder."""
        c = self.centre + 0.5 * self.slab[:, None] * self.normal
        return c, np.sqrt(self.radius ** 2 + (0.5 * self.slab) ** 2) + self.eps


def disc_radius(texels: TexelSet, settings) -> np.ndarray:
    """Each texel's disc radius: `radius` metres, or `radius_texels` of its own lightmap (unset: the
    paper's 1.5; the bake sets it from the direct-light mode)."""
    if settings.radius is not None:
        return np.full(len(texels), float(settings.radius))
    wide = settings.radius_texels if settings.radius_texels is not None else 1.5
    return texels.per_texel([lm.texel_size for lm in texels.lightmaps]) * float(wide)


def capped_radius(radius: np.ndarray, extent=None) -> np.ndarray:
    """The disc radius no wider than the texel's own piece of surface (`extent`, rise.piece_extent),
    and no narrower than CLEARANCE_FLOOR of the setting's radius."""
    if extent is None:
        return radius
    return np.minimum(radius, np.maximum(extent, CLEARANCE_FLOOR * radius))


def make_discs(texels: TexelSet, settings, scene_radius: float, clearance=None, rise=None, extent=None) -> Discs:
    """`clearance`: per texel, how far the surface runs in its tangent plane before other
    geometry stands in the way (texels.tangent_clearance); discs are cut to it, so a floor's disc
    does not reach past the wall beside it into light on the wall's other side. `rise`: per texel,
    how far its own surface rises in front of the disc (rise.py); the slab is cut to it. `extent`:
    per texel, the size of its own piece of surface (rise.piece_extent); no disc is wider."""
    if settings.kernel not in KERNELS:
        raise BakeError(f"setting 'kernel' = {settings.kernel!r}: choose {', '.join(KERNELS)}")
    radius = capped_radius(disc_radius(texels, settings), extent)
    if clearance is not None:
        floor = CLEARANCE_FLOOR * radius
        if texels.cuts is not None:
            cut = texels.cuts.of >= 0
            floor[cut] = CUT_FLOOR * radius[cut]
        radius = np.minimum(radius, np.maximum(clearance, floor))
    if not np.all(radius > 0):
        raise BakeError("disc radius is zero: a lightmap has no texel area (check its UVs)")
    eps = 1e-6 * max(scene_radius, 1e-3)
    if rise is None:
        slab = SLAB * radius
    else:
        # In steps of r/100, rounded up, with float noise on flat surfaces taken as flat: the discs
        # of a flat chart keep one slab, which lattice patches (patches.py) need to take them in.
        step = RISE_STEP * radius
        steps = np.ceil(np.maximum(np.asarray(rise, np.float64) - 1e-4 * radius, 0.0) / step)
        slab = np.minimum(SLAB * radius, steps * step + FLAT_SLAB * radius)
    return Discs(np.ascontiguousarray(texels.position, np.float64),
                 np.ascontiguousarray(texels.normal, np.float64),
                 radius.astype(np.float64), slab.astype(np.float64), eps, KERNELS[settings.kernel])


@numba.njit(cache=True, inline="always")
def add_l1(acc_l1, j, k, flux, w, i):
    """A directional bake's L1 (lightmap/sh.py): the crossing's weighted flux times the way back
    along segment i, into acc_l1[disc j, axis·3 + colour]; nothing when acc_l1 has no rows (a plain
    bake passes an empty array, so the kernels stay one compiled version)."""
    if acc_l1.shape[0] > 0:
        for a in range(3):
            back = -k * w[i, a]
            for c in range(3):
                acc_l1[j, 3 * a + c] += back * flux[i, c]


def l1_sums(n: int, directional: bool) -> np.ndarray:
    """The L1 sums of n discs, (n, 9), or the empty array of a plain bake (add_l1)."""
    return np.zeros((n, 9) if directional else (0, 9))


@numba.njit(cache=True, inline="always")
def crossing_weight(ox, oy, oz, wx, wy, wz, length, cx, cy, cz, nx, ny, nz, r, slab, eps, kernel):
    """Kernel weight of the segment for the disc, 0.0 when it does not cross (see module doc)."""
    wn = wx * nx + wy * ny + wz * nz
    if wn >= 0.0:
        return 0.0
    dx, dy, dz = cx - ox, cy - oy, cz - oz
    t = (dx * nx + dy * ny + dz * nz) / wn
    if t <= 0.0:
        return 0.0
    if t <= length + eps:
        px, py, pz = ox + t * wx - cx, oy + t * wy - cy, oz + t * wz - cz
    else:
        # Ends before the plane: count it if the end lies within the slab above the disc.
        ex, ey, ez = ox + length * wx - cx, oy + length * wy - cy, oz + length * wz - cz
        h = ex * nx + ey * ny + ez * nz
        if h > slab:
            return 0.0
        px, py, pz = ex - h * nx, ey - h * ny, ez - h * nz
    d2 = px * px + py * py + pz * pz
    r2 = r * r
    if d2 > r2:
        return 0.0
    if kernel == 1:
        return 2.0 * (1.0 - d2 / r2) / (np.pi * r2)
    return 1.0 / (np.pi * r2)

