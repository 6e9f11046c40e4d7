"""Images that colour and cut surfaces: textured albedo and alpha at a ray's hit, as Cycles reads them.

The exporter packs every image a material reads into one float32 RGBA array (`Textures`), converted
to linear light (sRGB images decoded, as Cycles does) and laid out with row 0 at the bottom, as
Blender's `Image.pixels` are. A triangle then names the texture that scales its albedo and the one
whose alpha channel scales its opacity, with UVs per corner (`Scene.tex_uvs`). The tracer and the
shadow rays look textures up here, in compiled code, from the barycentrics Embree returns.

Lookups follow Blender's Image Texture node: Linear (bilinear between texel centres) or Closest
interpolation; Repeat, Extend (clamp to the edge) or Clip (transparent black outside [0, 1]) extension.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..sampling import inline, jit

REPEAT, EXTEND, CLIP = 0, 1, 2
CLOSEST, LINEAR = 0, 1
EXTENSIONS = {"REPEAT": REPEAT, "EXTEND": EXTEND, "CLIP": CLIP, "MIRROR": REPEAT, "CHECKER": REPEAT}
INTERPOLATIONS = {"Closest": CLOSEST, "Linear": LINEAR, "Cubic": LINEAR, "Smart": LINEAR}


@dataclass
class Textures:
    """pixels: (P, 4) float32 linear RGBA of every image, one after another, row 0 at the bottom;
    info: (K, 5) int64 rows (offset into pixels, width, height, extension, interpolation)."""
    pixels: np.ndarray
    info: np.ndarray

    @staticmethod
    def pack(images: list, extensions: list = None, interpolations: list = None) -> "Textures":
        """Images as (H, W, 4) (or 3-channel) float arrays, each with an extension and interpolation."""
        extensions = extensions or [REPEAT] * len(images)
        interpolations = interpolations or [LINEAR] * len(images)
        parts, info, offset = [], [], 0
        for img, ext, interp in zip(images, extensions, interpolations):
            img = np.asarray(img, np.float32)
            h, w = img.shape[:2]
            if img.shape[2] == 3:
                img = np.concatenate([img, np.ones((h, w, 1), np.float32)], axis=2)
            parts.append(img.reshape(-1, 4))
            info.append((offset, w, h, int(ext), int(interp)))
            offset += w * h
        pixels = np.concatenate(parts) if parts else np.zeros((1, 4), np.float32)
        return Textures(np.ascontiguousarray(pixels), np.array(info, np.int64).reshape(-1, 5))


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB transfer function undone (IEC 61966-2-1), as Blender's 'sRGB' colour space does."""
    c = np.asarray(c, np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4).astype(np.float32)


@inline
def _texel(pixels, offset, w, h, ext, x, y, c):
    """Channel c of texel (x, y) with the extension rule; Clip gives 0 outside."""
    if ext == REPEAT:
        x = x % w
        y = y % h
    elif ext == EXTEND:
        x = min(max(x, 0), w - 1)
        y = min(max(y, 0), h - 1)
    elif x < 0 or y < 0 or x >= w or y >= h:
        return 0.0
    return pixels[offset + y * w + x, c]


@inline
def lookup(pixels, info, k, s, t, c):
    """Channel c (0-3) of texture k at UV (s, t)."""
    offset, w, h, ext, interp = info[k, 0], info[k, 1], info[k, 2], info[k, 3], info[k, 4]
    if ext == CLIP and (s < 0.0 or s > 1.0 or t < 0.0 or t > 1.0):
        return 0.0
    fx = s * w
    fy = t * h
    if interp == CLOSEST:
        return _texel(pixels, offset, w, h, ext, np.int64(math.floor(fx)), np.int64(math.floor(fy)), c)
    fx -= 0.5
    fy -= 0.5
    x0 = np.int64(math.floor(fx))
    y0 = np.int64(math.floor(fy))
    ax = fx - x0
    ay = fy - y0
    a = _texel(pixels, offset, w, h, ext, x0, y0, c)
    b = _texel(pixels, offset, w, h, ext, x0 + 1, y0, c)
    d = _texel(pixels, offset, w, h, ext, x0, y0 + 1, c)
    e = _texel(pixels, offset, w, h, ext, x0 + 1, y0 + 1, c)
    return (a * (1.0 - ax) + b * ax) * (1.0 - ay) + (d * (1.0 - ax) + e * ax) * ay


@inline
def hit_uv(tex_uvs, t, u, v):
    """Texture UV at barycentrics (u, v) of triangle t (Embree's: p = (1−u−v)·p0 + u·p1 + v·p2)."""
    w = 1.0 - u - v
    return (w * tex_uvs[t, 0, 0] + u * tex_uvs[t, 1, 0] + v * tex_uvs[t, 2, 0],
            w * tex_uvs[t, 0, 1] + u * tex_uvs[t, 1, 1] + v * tex_uvs[t, 2, 1])


@inline
def opacity_at(opacity, opacity_tex, tex_uvs, pixels, info, t, u, v):
    """How much of the light reaching triangle t at (u, v) the surface stops (1: opaque)."""
    a = np.float64(opacity[t])
    k = opacity_tex[t]
    if k >= 0 and a > 0.0:
        s, q = hit_uv(tex_uvs, t, u, v)
        a *= min(max(lookup(pixels, info, k, s, q, 3), 0.0), 1.0)
    return a


@jit
def sample(pixels, info, k, s, t):
    """(N, 4) lookups of texture k at UVs s, t (arrays): for tests and the exporter's averages."""
    out = np.empty((s.shape[0], 4))
    for i in range(s.shape[0]):
        for c in range(4):
            out[i, c] = lookup(pixels, info, k, s[i], t[i], c)
    return out


@dataclass
class Surfaces:
    """Per-triangle texture references and opacity in the form the kernels take (never None)."""
    pixels: np.ndarray
    info: np.ndarray
    tex_uvs: np.ndarray  # (T, 3, 2) float64
    albedo_tex: np.ndarray  # (T,) int32, −1: none
    opacity: np.ndarray  # (T,) float32
    opacity_tex: np.ndarray  # (T,) int32, −1: none
    textured: bool  # some triangle's albedo comes from a texture
    cutout: bool  # some triangle lets light through


def surfaces(scene) -> Surfaces:
    t = scene.triangle_count
    tex = scene.textures
    pixels = tex.pixels if tex is not None else np.zeros((1, 4), np.float32)
    info = tex.info if tex is not None else np.zeros((1, 5), np.int64)
    uvs = scene.tex_uvs if scene.tex_uvs is not None else np.zeros((max(t, 1), 3, 2))
    alb = scene.albedo_texture if scene.albedo_texture is not None else np.full(max(t, 1), -1, np.int32)
    op = scene.opacity if scene.opacity is not None else np.ones(max(t, 1), np.float32)
    op_tex = scene.opacity_texture if scene.opacity_texture is not None else np.full(max(t, 1), -1, np.int32)
    op = np.ascontiguousarray(op, np.float32)
    op_tex = np.ascontiguousarray(op_tex, np.int32)
    return Surfaces(pixels, info, np.ascontiguousarray(uvs, np.float64), np.ascontiguousarray(alb, np.int32), op,
                    op_tex, bool(np.any(alb >= 0)), bool(np.any(op < 1.0) or np.any(op_tex >= 0)))
