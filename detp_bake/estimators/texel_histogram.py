"""Texel histogram: each photon adds its flux to the one texel it lands in.

E(texel) = Σ Φ_p / A over the photons that land on the texel's own square of surface from the front,
A being the world area of surface inside that square (texels.py measures it exactly). That is the
mean irradiance over the square, which is what Cycles' bake averages too (it jitters its sample
points over the texel), so there is no blur beyond the texel and no darkening in concave corners.

It costs one lookup per landing and nothing per texel, where a DETP disc of r texels is crossed by
some πr² times as many segments and each must be found in an index. Its noise is the price: about
1/√(photons landing on the texel), and independent from texel to texel. That white noise is what
OIDN is trained to remove (docs/design.md, Denoising: noise correlated over a disc passes through it), so this
estimator is meant to be denoised: it is the indirect part of a bake whose direct light comes from
shadow rays, and the bake denoises the two parts apart (finishing.Finishing), since OIDN smooths white
noise over a smooth field far better than next to the sharp edges of direct light (L-shaped room,
1M photons: 1.65 % against 2.24 % RMSE to Cycles). With `--direct photons` or without denoising it
is the noisiest of the estimators.
"""
from __future__ import annotations

import sys
import time

import numba
import numpy as np

from ..transport.textures import hit_uv, opacity_at, surfaces
from ..lightmap.texels import lightmap_triangles
from ..lightmap.validity import Cuts, on_side
from .base import Estimate, Estimator, register

# A landing's weight cos(shading normal) / cos(face normal) is capped: on a face tilted 30° from its
# shading normal (a six-sided smooth cylinder) the cap binds only within 7° of grazing the face.
MAX_TILT = 4.0


@numba.njit(cache=True, parallel=True)
def _landing_texels(pos, direction, tri, positions, normals, uvs, lm_of_tri, width, base, texel_of, area,
                    cut_share, cut_of, cut_p, cut_n, cutout, opacity, opacity_tex, tex_uvs, pixels, info, texel, weight):
    """Per landing, its texel (−1: none of ours, or from behind) and the weight of its flux: one over
    the texel's area, the ratio of its cosines to the shading and the face normal, and on a cut-out
    surface one over its opacity α too. A photon lands there with
    probability α and passes through otherwise (scattering.py), so a landing counts 1/α times and
    stands for every arrival, on average. A landing beyond its texel's cut (a wall standing on the
    square: validity.py) is not the texel's light and is left out."""
    for h in numba.prange(tri.shape[0]):
        texel[h] = -1
        t = tri[h]
        m = lm_of_tri[t]
        if m < 0:
            continue
        # Barycentrics of the landing point in its triangle (3D, float64).
        ax, ay, az = np.float64(positions[t, 0, 0]), np.float64(positions[t, 0, 1]), np.float64(positions[t, 0, 2])
        e1x, e1y, e1z = positions[t, 1, 0] - ax, positions[t, 1, 1] - ay, positions[t, 1, 2] - az
        e2x, e2y, e2z = positions[t, 2, 0] - ax, positions[t, 2, 1] - ay, positions[t, 2, 2] - az
        px, py, pz = pos[h, 0] - ax, pos[h, 1] - ay, pos[h, 2] - az
        d11 = e1x * e1x + e1y * e1y + e1z * e1z
        d12 = e1x * e2x + e1y * e2y + e1z * e2z
        d22 = e2x * e2x + e2y * e2y + e2z * e2z
        p1 = px * e1x + py * e1y + pz * e1z
        p2 = px * e2x + py * e2y + pz * e2z
        det = d11 * d22 - d12 * d12
        if det <= 0.0:
            continue
        b1 = (d22 * p1 - d12 * p2) / det
        b2 = (d11 * p2 - d12 * p1) / det
        b1 = min(max(b1, 0.0), 1.0)
        b2 = min(max(b2, 0.0), 1.0 - b1)
        b0 = 1.0 - b1 - b2
        # From the front of the surface the texel faces (its interpolated shading normal), and
        # counted as Cycles counts light on a smooth-shaded surface: by the cosine to the shading
        # normal, where the landing carries the flux through the face (the geometric cosine).
        nx = b0 * normals[t, 0, 0] + b1 * normals[t, 1, 0] + b2 * normals[t, 2, 0]
        ny = b0 * normals[t, 0, 1] + b1 * normals[t, 1, 1] + b2 * normals[t, 2, 1]
        nz = b0 * normals[t, 0, 2] + b1 * normals[t, 1, 2] + b2 * normals[t, 2, 2]
        dx, dy, dz = direction[h, 0], direction[h, 1], direction[h, 2]
        cos_s = -(nx * dx + ny * dy + nz * dz)
        if cos_s <= 0.0:
            continue
        gx, gy, gz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        if gx * nx + gy * ny + gz * nz < 0.0:
            gx, gy, gz = -gx, -gy, -gz
        cos_g = -(gx * dx + gy * dy + gz * dz)
        if cos_g <= 0.0:
            continue  # it reached the face from behind
        cos_s /= np.sqrt(nx * nx + ny * ny + nz * nz)
        cos_g /= np.sqrt(gx * gx + gy * gy + gz * gz)
        tilt = min(cos_s / cos_g, MAX_TILT)
        w = width[m]
        u, v = hit_uv(uvs, t, b1, b2)  # lightmap UVs at the landing
        u *= w
        v *= w
        i = min(max(int(np.floor(u)), 0), w - 1)
        j = min(max(int(np.floor(v)), 0), w - 1)
        k = texel_of[base[m] + j * w + i]
        if k < 0:
            continue
        if not on_side(cut_of, cut_p, cut_n, k, pos[h, 0], pos[h, 1], pos[h, 2]):
            continue
        # One over the area of the texel's side of its cut (float64), found here rather than
        # kept for every texel (8 bytes a texel at 2048²).
        side = np.float64(area[k])
        if cut_of[k] >= 0:
            side *= cut_share[cut_of[k]]
        a = (1.0 / max(side, 1e-30)) * tilt
        if cutout:
            alpha = opacity_at(opacity, opacity_tex, tex_uvs, pixels, info, t, b1, b2)
            if alpha <= 0.0:
                continue
            a /= alpha
        texel[h] = k
        weight[h] = a


@numba.njit(cache=True)
def _add(texel, weight, flux, acc):
    """The sums, in landing order on one thread: the same on any machine. Returns how many counted."""
    counted = 0
    for h in range(texel.shape[0]):
        k = texel[h]
        if k >= 0:
            a = weight[h]
            acc[k, 0] += flux[h, 0] * a
            acc[k, 1] += flux[h, 1] * a
            acc[k, 2] += flux[h, 2] * a
            counted += 1
    return counted


@numba.njit(cache=True)
def _add_l1(texel, weight, flux, direction, acc):
    """L1 of the same landings (lightmap/sh.py): the flux times the way back along the photon's
    flight, into acc[texel, axis·3 + colour], in landing order."""
    for h in range(texel.shape[0]):
        k = texel[h]
        if k >= 0:
            a = weight[h]
            for x in range(3):
                back = -direction[h, x]
                for c in range(3):
                    acc[k, 3 * x + c] += flux[h, c] * a * back


class _Spares:
    """The block sums `take` handed over last, filled again once nobody else holds them (the bake has
    added them into its totals and let them go): a block's first landing then goes into them,
    cleared, instead of into new zeros, which are mapped fresh, so that every page the block touched
    faulted once. At 557k texels that was 3,300 faults a block and about 0.4 s of a 1024² bake's
    main thread, where clearing an array takes a millisecond. Nothing more is held at once than with
    new zeros: the spare is taken up when the next block begins, after the bake let the last one go.
    An array held elsewhere (the bake's totals adopt the first block's) is never cleared."""

    FREE = None  # the reference count `_refs` reads for an array only this holds (_calibrated)

    def __init__(self):
        self.last = None

    def hand(self, sums: np.ndarray) -> None:
        self.last = sums

    def reuse(self, untouched: np.ndarray) -> np.ndarray:
        """The spare, cleared, where it is shaped as `untouched` (new zeros no landing has touched)
        and free; else `untouched`."""
        free = _Spares._calibrated()
        if free is None or self.last is None or self.last.shape != untouched.shape or self._refs() != free:
            return untouched
        a, self.last = self.last, None
        a.fill(0.0)
        return a

    def _refs(self) -> int:
        a = self.last
        return sys.getrefcount(a)

    @classmethod
    def _calibrated(cls):
        """What `_refs` reads for an array nobody else holds, once; None where it does not read more
        for one held elsewhere too (an interpreter that counts otherwise): then nothing is reused."""
        if cls.FREE is None:
            probe = cls()
            probe.hand(np.zeros(1))
            free = probe._refs()
            elsewhere = [probe.last]  # the same array held once more
            cls.FREE = free if elsewhere and probe._refs() > free else -1
        return cls.FREE if cls.FREE >= 0 else None

    def clear(self) -> None:
        self.last = None


def _adopt_or_add(own: np.ndarray, given: np.ndarray, fresh: bool) -> np.ndarray:
    """`given` itself where `own` holds nothing yet and `given` may be kept, else own + given."""
    if fresh and given.flags.writeable and given.flags.owndata and given.shape == own.shape:
        return given
    own += given
    return own


@register
class TexelHistogram(Estimator):
    name = "texel_histogram"
    # The block sums and the bake's running sums (24 each), the noise sums (8), the pixel table (4 a pixel):
    # measured, benchmarks/memory.py
    bytes_per_texel = 60
    streaming = True
    segments = False  # the hits alone
    every_texel = True  # its estimate costs nothing per texel: no sites between which to blend
    texel_geometry_while_tracing = False  # landings find their texel from the scene's triangles
    for_denoiser = True
    directional = True

    def __init__(self, texels, settings, progress=None, context=None):
        super().__init__(texels, settings, progress, context)
        sc = self.context.scene
        if sc is None:
            raise ValueError("texel_histogram needs the scene's triangles (Context.scene)")
        lm_of_tri = np.full(sc.triangle_count, -1, np.int32)
        width = np.zeros(len(texels.lightmaps), np.int64)
        base = np.zeros(len(texels.lightmaps), np.int64)
        total = 0
        for m, lm in enumerate(texels.lightmaps):
            if lm.width != lm.height:
                raise ValueError("texel_histogram needs square lightmaps")
            lm_of_tri[lightmap_triangles(sc, lm)] = m
            width[m], base[m] = lm.width, total
            total += lm.width * lm.height
        texel_of = np.full(total, -1, np.int32)
        for m, lm in enumerate(texels.lightmaps):
            texel_of[base[m] + texels.pixel[lm.texels]] = np.arange(lm.offset, lm.offset + lm.count, dtype=np.int32)
        # The scene's own arrays, not copies (the bake's are float64 positions, float32 normals and UVs).
        # A texel cut by a wall (validity.py) counts the landings on its own side, over that side's area.
        cuts = texels.cuts if texels.cuts is not None else Cuts.none(len(texels))
        share = np.ascontiguousarray(cuts.share if len(cuts.share) else np.ones(1), np.float64)
        self._tables = (np.ascontiguousarray(sc.positions), np.ascontiguousarray(sc.normals),
                        np.ascontiguousarray(sc.uvs), lm_of_tri, width, base, texel_of,
                        np.ascontiguousarray(texels.area), share, *cuts.kernel_arrays())
        srf = surfaces(sc)
        self._surfaces = (srf.cutout, srf.opacity, srf.opacity_tex, srf.tex_uvs, srf.pixels, srf.info)
        self.acc = np.zeros((len(texels), 3))
        self.acc_l1 = np.zeros((len(texels), 9)) if self.context.directional else None
        self._spares, self._spares_l1 = _Spares(), _Spares()
        self._untouched = False  # self.acc (and acc_l1) are new zeros from `take`, untouched
        self.landings = self.counted = 0
        self.seconds = 0.0

    def add(self, batch):
        t0 = time.perf_counter()
        n = batch.hit_count
        texel, weight = np.empty(n, np.int32), np.empty(n)
        if self._untouched:
            self.acc = self._spares.reuse(self.acc)
            if self.acc_l1 is not None:
                self.acc_l1 = self._spares_l1.reuse(self.acc_l1)
            self._untouched = False
        _landing_texels(batch.hit_position, batch.hit_dir, batch.hit_triangle, *self._tables, *self._surfaces, texel,
                        weight)
        self.counted += _add(texel, weight, batch.hit_flux, self.acc)
        if self.acc_l1 is not None:
            _add_l1(texel, weight, batch.hit_flux, batch.hit_dir, self.acc_l1)
        self.landings += batch.hit_count
        self.seconds += time.perf_counter() - t0

    def take(self):
        """Hands its sums over, not a copy (the bake adopts or adds them), and starts again from
        zeros that take no memory until a photon lands, and then become an earlier block's sums the
        bake let go, cleared, where there is one (_Spares)."""
        sums = {"irradiance": self.acc, "landings": self.landings, "counted": self.counted,
                "seconds_query": self.seconds}
        self._spares.hand(self.acc)
        self.acc = np.zeros(self.acc.shape)
        if self.acc_l1 is not None:
            self._spares_l1.hand(self.acc_l1)
            sums["l1"], self.acc_l1 = self.acc_l1, np.zeros(self.acc_l1.shape)
        self._untouched = True
        self.landings = self.counted = 0
        self.seconds = 0.0
        return sums

    def absorb(self, sums):
        self._spares.clear()  # the tracing is over
        self._spares_l1.clear()
        self._untouched = False  # the sums may become its own: never to be swapped for a spare
        fresh = self.landings == 0  # nothing of its own yet: the sums become its own (0 + x is x)
        self.acc = _adopt_or_add(self.acc, sums["irradiance"], fresh)
        if self.acc_l1 is not None:
            self.acc_l1 = _adopt_or_add(self.acc_l1, sums["l1"], fresh)
        self.landings += sums["landings"]
        self.counted += sums["counted"]
        self.seconds += sums["seconds_query"]

    def reset(self) -> None:
        self.take()

    def finish(self):
        """Hands its sums over, not a copy, and starts again from zero (untouched zeros take no memory)."""
        self._spares.clear()
        self._spares_l1.clear()
        acc, self.acc = self.acc, np.zeros(self.acc.shape)  # calloc: no page touched
        l1, self.acc_l1 = self.acc_l1, None if self.acc_l1 is None else np.zeros(self.acc_l1.shape)
        return Estimate(acc, {"landings": self.landings, "counted": self.counted, "seconds_query": self.seconds},
                        l1=l1)
