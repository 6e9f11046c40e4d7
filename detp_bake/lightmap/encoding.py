"""Lightmaps as 8-bit images for formats that carry no floats (the glTF export, docs/gltf.md).

A lightmap is linear and goes well past 1, so it is stored as RGBE, Radiance's shared exponent:
alpha = E = e + 128 where 2^e bounds the texel's largest channel, rgb = each channel's mantissa
c · 2^(8 − e) rounded to the nearest integer (Radiance truncates; rounding halves the worst error).
Decoding is exactly c = byte · 2^(E − 136), and E = 0 is black. Each channel is then within half a
mantissa step, at most 1/255.5 (0.39 %) of the texel's largest channel; negative light is stored as 0. The image must be read
unpremultiplied (alpha is an exponent, not a coverage).

The SH L1 maps of a `--directional sh` bake go along as ratios r = L1ₐ/L0 per axis and colour
channel (`ratio_encode`): |L1| ≤ L0 bounds r to [−1, 1] whatever the light's brightness, so 8 bits
store it to within 1/255 with no exponent, and the viewer multiplies back by the decoded L0.

The other encodings here (RGBM, 16-bit linear, 8-bit sRGB under an exposure) exist to measure
against (benchmarks/encoding.py); `lit_error` is the measure.
"""
from __future__ import annotations

import struct
import zlib

import numpy as np

BIAS = 128  # E = e + BIAS
MANTISSA = 8  # bits of each channel's mantissa
LIT = 0.01  # texels above this share of the lightmap's brightest count in `lit_error`


def rgbe_encode(rgb: np.ndarray) -> np.ndarray:
    """Float rgb (…, 3) → uint8 RGBE (…, 4), mantissas rounded to nearest."""
    rgb = np.nan_to_num(np.asarray(rgb, np.float64)[..., :3], nan=0.0, posinf=0.0, neginf=0.0)
    rgb = np.maximum(rgb, 0.0)
    peak = rgb.max(axis=-1)
    _, e = np.frexp(peak)  # peak = m · 2^e, 0.5 <= m < 1
    q = np.rint(np.ldexp(rgb, (MANTISSA - e)[..., None]))
    carry = q.max(axis=-1) > 255  # the peak rounded up to 256: one exponent more
    e = e + carry
    q = np.where(carry[..., None], np.rint(np.ldexp(rgb, (MANTISSA - e)[..., None])), q)
    too_big = e > 255 - BIAS
    q = np.where(too_big[..., None], 255.0, q)
    e = np.minimum(e, 255 - BIAS)
    black = (peak <= 0.0) | (e < 1 - BIAS) | (q.max(axis=-1) == 0)
    out = np.empty(rgb.shape[:-1] + (4,), np.uint8)
    out[..., :3] = np.where(black[..., None], 0, q).astype(np.uint8)
    out[..., 3] = np.where(black, 0, e + BIAS).astype(np.uint8)
    return out


def rgbe_decode(rgbe: np.ndarray) -> np.ndarray:
    """uint8 RGBE (…, 4) → float32 rgb (…, 3): byte · 2^(E − 136), E = 0 black."""
    rgbe = np.asarray(rgbe)
    e = rgbe[..., 3].astype(np.int32)
    scale = np.where(e == 0, 0.0, np.ldexp(1.0, e - BIAS - MANTISSA))
    return (rgbe[..., :3].astype(np.float64) * scale[..., None]).astype(np.float32)


def ratio_encode(l0: np.ndarray, l1: np.ndarray) -> np.ndarray:
    """One axis of L1 over L0, each (…, 3) → uint8 (…, 3): round((r + 1)/2 · 255) with r = L1ₐ/L0
    clamped to [−1, 1] and 0 where L0 ≤ 0 (no light there: no direction to keep)."""
    l0 = np.nan_to_num(np.asarray(l0, np.float64)[..., :3])
    l1 = np.nan_to_num(np.asarray(l1, np.float64)[..., :3])
    lit = l0 > 0.0
    r = np.clip(np.where(lit, l1 / np.where(lit, l0, 1.0), 0.0), -1.0, 1.0)
    return np.rint((r + 1.0) * 127.5).astype(np.uint8)


def ratio_decode(q: np.ndarray) -> np.ndarray:
    """uint8 from `ratio_encode` → float32 r = q/127.5 − 1, within 1/255 of the clamped ratio (half
    a step; r = 0 itself lands on 128, 1/255 off)."""
    return (np.asarray(q).astype(np.float64) / 127.5 - 1.0).astype(np.float32)


def rgbm_roundtrip(rgb: np.ndarray, scale: float) -> np.ndarray:
    """rgb through linear RGBM with range `scale` (8 or 16), 8 bits each: what it would show."""
    rgb = np.clip(np.asarray(rgb, np.float64)[..., :3] / scale, 0.0, 1.0)
    m = np.ceil(np.clip(rgb.max(axis=-1), 1e-6, 1.0) * 255.0) / 255.0
    q = np.rint(rgb / m[..., None] * 255.0) / 255.0
    return (q * m[..., None] * scale).astype(np.float32)


def linear16_roundtrip(rgb: np.ndarray) -> np.ndarray:
    """rgb as 16-bit linear integers under one exposure (the brightest channel at 65535)."""
    rgb = np.maximum(np.asarray(rgb, np.float64)[..., :3], 0.0)
    exposure = 65535.0 / max(float(rgb.max()), 1e-30)
    return (np.rint(rgb * exposure) / exposure).astype(np.float32)


def srgb8_roundtrip(rgb: np.ndarray) -> np.ndarray:
    """rgb as 8-bit sRGB under one exposure (the brightest channel at 255), the exposure kept
    as a material's lightmap intensity."""
    rgb = np.maximum(np.asarray(rgb, np.float64)[..., :3], 0.0)
    intensity = max(float(rgb.max()), 1e-30)
    x = rgb / intensity
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    s = np.rint(s * 255.0) / 255.0
    lin = np.where(s <= 0.04045, s / 12.92, np.power((s + 0.055) / 1.055, 2.4))
    return (lin * intensity).astype(np.float32)


def lit_error(reference: np.ndarray, decoded: np.ndarray) -> dict:
    """How far `decoded` is from `reference` where there is light: over texels whose brightest
    channel is above LIT of the lightmap's brightest, the mean and the largest absolute error of a
    channel, each as a share of the mean channel value there."""
    ref = np.asarray(reference, np.float64)[..., :3]
    dec = np.asarray(decoded, np.float64)[..., :3]
    peak = ref.max(axis=-1)
    lit = peak > LIT * max(float(peak.max()), 0.0)
    if not lit.any():
        return {"mean": 0.0, "max": 0.0, "texels": 0}
    mean = float(ref[lit].mean())
    err = np.abs(dec[lit] - ref[lit])
    return {"mean": float(err.mean()) / mean, "max": float(err.max()) / mean, "texels": int(lit.sum())}


def png_bytes(pixels: np.ndarray) -> bytes:
    """uint8 (h, w, 4) as an RGBA PNG, or (h, w, 3) as an RGB one, row 0 at the top. Written here
    rather than by an image library, which would take the alpha for coverage and change the colours."""
    pixels = np.ascontiguousarray(pixels, np.uint8)
    h, w, c = pixels.shape
    if c not in (3, 4):
        raise ValueError("png_bytes wants RGBA or RGB pixels")
    rows = np.concatenate([np.zeros((h, 1), np.uint8), pixels.reshape(h, w * c)], axis=1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    header = struct.pack(">IIBBBBB", w, h, 8, 6 if c == 4 else 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6))
            + chunk(b"IEND", b""))
