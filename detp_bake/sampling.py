"""Vectorised direction and shape sampling shared by light emission and diffuse bounces."""
from __future__ import annotations

import numpy as np


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents per unit normal (rows), branch-free (Duff et al. 2017)."""
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    s = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, s


def to_world(local: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Rotate directions given in a frame whose z axis is `n` into world space."""
    t, s = orthonormal_basis(n)
    return local[:, :1] * t + local[:, 1:2] * s + local[:, 2:3] * n


def cosine_hemisphere(n: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions about unit normals `n` (rows)."""
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - u1))], axis=1)
    return to_world(local, n)


def uniform_sphere(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    z = 1.0 - 2.0 * u1
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def uniform_cone(axis: np.ndarray, cos_max: float, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Directions uniform in solid angle within `acos(cos_max)` of the unit `axis`."""
    cos_t = 1.0 - u1 * (1.0 - cos_max)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * u2
    local = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)
    return to_world(local, np.broadcast_to(axis, local.shape).astype(np.float64))


def uniform_disc(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points uniform on the unit disc (concentric map, area preserving)."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    first = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(first, a, b)
        theta = np.where(first, (np.pi / 4) * (b / a), np.pi / 2 - (np.pi / 4) * (a / b))
    theta = np.nan_to_num(theta)
    return r * np.cos(theta), r * np.sin(theta)


def uniform_triangle(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Barycentric weights uniform over a triangle."""
    su = np.sqrt(u1)
    b0 = 1.0 - su
    b1 = u2 * su
    return b0, b1, 1.0 - b0 - b1
