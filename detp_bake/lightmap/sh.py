"""Directional lightmaps: the first-order (L1) spherical-harmonic convention every part of the bake
shares, the physical clamp, and the shading the Apply node group evaluates.

Convention. A texel with unit normal n receives radiance L(ω) from directions ω. Its plain lightmap
holds E/π, E = ∫ L(ω) max(n·ω, 0) dω (docs/design.md, Units). Let f(ω) = L(ω) max(n·ω, 0)/π, the
cosine-weighted incoming light the plain lightmap integrates. A directional lightmap stores its
bands 0 and 1, per colour channel:

    L0 = ∫ f(ω) dω          (= E/π: exactly the plain lightmap, same unit, same numbers)
    L1 = ∫ f(ω) ω dω        (a world-space vector, same unit)

These are the SH projections of f up to one constant per band (f₀₀ = L0/(2√π), f₁ₘ = √(3/4π) L1ₘ in
the real basis Y₁ₘ ∝ (y, z, x)), so f ≈ (L0 + 3 L1·ω)/(4π); storing L0 and L1 rather than the
coefficients keeps L0 the plain lightmap. Each sample of light the bake already adds to E (a shadow
ray that reaches its light, a photon landing, a segment crossing a disc, a gathered hit) adds its
share e to L0 and e·ω to L1, ω the unit direction towards where the light came from.

Bounds: f ≥ 0 and |ω| = 1 give |L1| ≤ L0 (equality: all light from one direction). A noisy or
denoised estimate may break it; `clamp` scales L1 back to |L1| ≤ L0 (L1 = 0 where L0 ≤ 0) and
counts the texels it changed.

Closed forms the tests hold the bake to (n the texel's normal):
- a delta light (sun without angle, point light) from unit direction d: L1 = L0·d, |L1|/L0 = 1;
- a uniform sky over an open plane (upper hemisphere, radiance R): L0 = R, L1 = (2/3)·R·n;
- a vertical wall (normal x) on a black infinite ground under the same sky (the quarter sphere
  x > 0, z > 0): L0 = R/2, L1 = R·(x/3 + 2z/(3π)): L1/L0 = (2/3)x + (4/(3π))z, tilted up from the
  normal by atan(2/π) = 32.48°, |L1|/L0 = 0.7904.

Shading with another normal n' (a normal map): each colour channel's light is read as a share
s = |L1|/L0 from the dominant direction d = L1/|L1| (a delta) and the rest from a uniform sky over
the texel's plane; for those two parts the exact irradiances are L0·(n'·d)/(n·d) and
L0·(1 + n'·n)/2. Since a uniform hemisphere has |L1|/L0 = 2/3 along n, the delta's weight a solves
|L1/L0 − (1 − a)(2/3)n| = a; `shade` evaluates the mix. It is exact for one delta light and for a
uniform sky, gives L0 back for n' = n, and it is what the Apply node group computes.
"""
from __future__ import annotations

import numpy as np

# The channel layout of <name>.<estimator>.L1.exr: three world-space components per colour channel.
L1_CHANNELS = tuple(f"L1{axis}.{colour}" for axis in "xyz" for colour in "RGB")
# The same L1 again as one RGB file per axis, <name>.<estimator>.L1x.exr …: Blender's image loader
# reads an EXR's R, G, B (A) and nothing else, and engines sample three colour textures.
AXIS_FILES = ("L1x", "L1y", "L1z")
DOMINANT_CHANNELS = ("dir.x", "dir.y", "dir.z", "directionality")
HEMISPHERE_RATIO = 2.0 / 3.0  # |L1|/L0 of a uniform sky over an open plane
WALL_TILT = float(np.arctan(2.0 / np.pi))  # radians: the wall under a sky on a black ground
MIN_COS = 0.05  # the dominant direction's cosine to the normal is read no lower (a grazing light)


def l1_image_layout(l1: np.ndarray) -> np.ndarray:
    """(..., 3 colours, 3 axes) → (..., 9) in the order of L1_CHANNELS (axis-major)."""
    return np.ascontiguousarray(np.swapaxes(l1, -1, -2).reshape(l1.shape[:-2] + (9,)))


def from_layout(image: np.ndarray) -> np.ndarray:
    """(..., 9) in the order of L1_CHANNELS → (..., 3 colours, 3 axes)."""
    return np.swapaxes(image.reshape(image.shape[:-1] + (3, 3)), -1, -2)


def clamp(l0: np.ndarray, l1: np.ndarray) -> np.ndarray:
    """Scale L1 (..., 3 colours, 3 axes) in place so that |L1| ≤ L0 per colour channel, L1 = 0
    where L0 ≤ 0 (L0: (..., 3)); returns (...) bool: the texels that had a channel changed."""
    norm = np.sqrt(np.sum(np.square(l1, dtype=np.float64), axis=-1))
    bound = np.maximum(l0, 0.0)
    over = norm > bound * (1.0 + 1e-6)
    if over.any():
        scale = np.where(over, bound / np.where(norm > 0.0, norm, 1.0), 1.0)
        l1 *= scale[..., None].astype(l1.dtype)
    return over.any(axis=-1)


def delta_weight(ratio: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The share a of the light read as a delta from the dominant direction: |r − (1 − a)(2/3)n| = a
    for r = L1/L0 (..., 3), n unit (..., 3); a in [0, 1]."""
    h = HEMISPHERE_RATIO
    rn = np.sum(ratio * normal, axis=-1)
    rr = np.sum(ratio * ratio, axis=-1)
    # |r − h n + a h n|² = a²: (h² − 1) a² + 2 h (rn − h) a + (rr − 2 h rn + h²) = 0
    qa, qb, qc = h * h - 1.0, 2.0 * h * (rn - h), rr - 2.0 * h * rn + h * h
    disc = np.sqrt(np.maximum(qb * qb - 4.0 * qa * qc, 0.0))
    return np.clip((-qb - disc) / (2.0 * qa), 0.0, 1.0)


def shade(l0: np.ndarray, l1: np.ndarray, normal: np.ndarray, shading: np.ndarray) -> np.ndarray:
    """E/π for shading normal n' (`shading`) at texels of normal n: per colour channel, L0
    (..., 3), L1 (..., 3 colours, 3 axes), normals (..., 3) unit. See the module's docstring."""
    safe = np.where(l0 > 0.0, l0, 1.0)[..., None]
    ratio = np.where(l0[..., None] > 0.0, l1 / safe, 0.0)
    n, s = normal[..., None, :], shading[..., None, :]
    a = delta_weight(ratio, n)
    d = ratio - (1.0 - a)[..., None] * HEMISPHERE_RATIO * n
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
    towards = np.maximum(np.sum(s * d, axis=-1), 0.0) / np.maximum(np.sum(n * d, axis=-1), MIN_COS)
    sky = 0.5 * (1.0 + np.sum(s * n, axis=-1))
    return l0 * (a * towards + (1.0 - a) * sky)


def from_dominant(l0: np.ndarray, direction: np.ndarray, share: np.ndarray) -> np.ndarray:
    """L1 (..., 3 colours, 3 axes) as a dominant-direction map gives it back: every colour channel
    from the one `direction` (..., 3) with the one directionality `share` (...), L0 (..., 3). What
    Apply shades a `dominant` bake with; exact where the light comes from one direction."""
    return l0[..., :, None] * share[..., None, None] * direction[..., None, :]


def dominant(l0: np.ndarray, l1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The `dominant` mode's map from L0 (N, 3) and L1 (N, 3, 3): the luminance-weighted L1 as a
    unit world-space direction (N, 3) and its directionality |L1_lum|/L0_lum in [0, 1] (N,)."""
    lum = np.array([0.2126, 0.7152, 0.0722])
    v = np.einsum("c,nca->na", lum, l1)
    total = l0 @ lum
    norm = np.linalg.norm(v, axis=1)
    direction = v / np.where(norm > 0.0, norm, 1.0)[:, None]
    share = np.where(total > 0.0, norm / np.where(total > 0.0, total, 1.0), 0.0)
    return direction.astype(np.float32), np.clip(share, 0.0, 1.0).astype(np.float32)
