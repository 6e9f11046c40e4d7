"""Second-order (L2) spherical harmonics of incident radiance: the convention probes share.

A probe at p holds the radiance L(ω) arriving at p from each direction ω, projected on the nine real
SH basis functions Y_k (k = l² + l + m: band 0, band 1 (y, z, x), band 2), per colour channel:

    c_k = ∫ L(ω) Y_k(ω) dω        coefficients (..., 9, 3), float32 on disk

in the lightmaps' unit (docs/design.md, Units: a lightmap texel holds E/π). A diffuse surface with
unit normal n at the probe receives E(n) = ∫ L(ω) max(n·ω, 0) dω ≈ Σ_k A_l c_k Y_k(n), with the
clamped cosine's band factors A_0 = π, A_1 = 2π/3, A_2 = π/4; `irradiance` returns E(n)/π, which is
the number a lightmap texel of that normal at p would hold. The same layout and basis order as
three.js' `SphericalHarmonics3` (whose `getIrradianceAt` gives E), so coefficients go to a viewer as
they are.

Each sample an estimator adds (a gathered ray, a shadow ray reaching its light, a photon segment
crossing the probe's sphere) carries radiance weight w from direction ω towards where it came
from, and adds w·Y_k(ω) to c_k (`project`).

Closed forms the tests hold the bake to:
- uniform radiance R from every direction: c_0 = 2√π·R, all else 0; E(n)/π = R for every n;
- light from one direction d giving E(n) = E0 max(n·d, 0) (a sun of strength E0, a far point
  light): c_k = E0·Y_k(d); the reconstruction is the clamped cosine truncated to band 2, which reads
  E(d) = (1 + 2 + 5/4)/4·E0 = 1.0625·E0 facing the light and E(−d) = (1 − 2 + 5/4)/4·E0 =
  0.0625·E0 behind it (where the truth is 0).
"""
from __future__ import annotations

import numpy as np

from ..sampling import inline

COEFFICIENTS = 9
# The real SH basis constants, band by band (Y_00; Y_1m; Y_2m).
_Y00 = 0.5 * np.sqrt(1.0 / np.pi)
_Y1 = np.sqrt(3.0 / (4.0 * np.pi))
_Y2A = 0.5 * np.sqrt(15.0 / np.pi)   # xy, yz, xz
_Y20 = 0.25 * np.sqrt(5.0 / np.pi)    # 3z² − 1
_Y22 = 0.25 * np.sqrt(15.0 / np.pi)   # x² − y²
# The clamped cosine's convolution factors per band, divided by π (so `irradiance` gives E/π).
BAND_OF = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2])
COSINE_OVER_PI = np.array([1.0, 2.0 / 3.0, 0.25])[BAND_OF]


def basis(direction: np.ndarray) -> np.ndarray:
    """Y_k at unit directions (..., 3) → (..., 9), float64, in three.js' order."""
    d = np.asarray(direction, dtype=np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([
        np.full_like(x, _Y00),
        _Y1 * y, _Y1 * z, _Y1 * x,
        _Y2A * x * y, _Y2A * y * z, _Y20 * (3.0 * z * z - 1.0), _Y2A * x * z, _Y22 * (x * x - y * y),
    ], axis=-1)


def project(direction: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The coefficients (9, 3) of samples of radiance `weight` (n, 3) arriving from unit
    `direction` (n, 3), summed: Σ w·Y_k(ω). A Monte Carlo estimate divides by its pdf first."""
    return basis(direction).T @ np.asarray(weight, dtype=np.float64)


def irradiance(coefficients: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """E(n)/π, the lightmap's number, for coefficients (..., 9, 3) and unit normals (..., 3) →
    (..., 3). Broadcasts: one probe and many normals, or one normal per probe."""
    y = basis(normal) * COSINE_OVER_PI
    return np.einsum("...k,...kc->...c", y, np.asarray(coefficients, dtype=np.float64))


def radiance(coefficients: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """L(ω) as band 2 reconstructs it, (..., 3): what a probe's sphere shows in the viewport."""
    return np.einsum("...k,...kc->...c", basis(direction), np.asarray(coefficients, dtype=np.float64))


def uniform(value: np.ndarray) -> np.ndarray:
    """The coefficients (9, 3) of uniform radiance `value` (3,) from every direction."""
    out = np.zeros((COEFFICIENTS, 3))
    out[0] = np.asarray(value, dtype=np.float64) * 2.0 * np.sqrt(np.pi)
    return out


@inline
def add_sh(out, i, x, y, z, w0, w1, w2):
    """out[i, k, c] += w_c · Y_k(x, y, z): radiance weight w arriving from unit direction (x, y, z).
    The compiled kernels' `project` (gather.py, photon_sphere.py, masked_bounce.py), inlined."""
    ys = (_Y00, _Y1 * y, _Y1 * z, _Y1 * x, _Y2A * x * y, _Y2A * y * z, _Y20 * (3.0 * z * z - 1.0),
          _Y2A * x * z, _Y22 * (x * x - y * y))
    for k in range(9):
        out[i, k, 0] += w0 * ys[k]
        out[i, k, 1] += w1 * ys[k]
        out[i, k, 2] += w2 * ys[k]
