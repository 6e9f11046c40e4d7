"""Random numbers and direction/shape sampling shared by light emission and diffuse bounces.

Every photon has its own random stream: SplitMix64 (a Weyl sequence through a 64-bit mixer) started
at a hash of (seed, photon id). Emission draws the first numbers, each bounce the next ones, and the
state travels with the photon's ray. A photon's path is thereby a function of the seed and its id
alone — whatever the batch size, the thread count or the order in which rays are traced — and the
numbers are made where they are used, in parallel, with nothing drawn ahead. Uniforms come two at a
time with 32 random bits each: as many as float32 records can show.

The sampling functions are scalar `numba` functions, inlined into the emission and bounce
kernels; each maps uniforms in [0, 1) to a point or direction.
"""
from __future__ import annotations

import math

import numba
import numpy as np

_GAMMA = np.uint64(0x9E3779B97F4A7C15)  # 2^64 / golden ratio, SplitMix64's increment
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S32 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(32)
_LOW32 = np.uint64(0xFFFFFFFF)
_UNIT32 = 1.0 / 4294967296.0  # 2^-32

# Kernels may fuse a multiply and an add (one rounding instead of two: as accurate, and faster).
jit = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
# Small helpers are inlined into their callers by Numba itself: a call between compiled
# functions costs more than the helpers' own arithmetic.
inline = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")


def seed_key(seed: int) -> np.uint64:
    """The 64-bit key every random number of a bake derives from."""
    return np.uint64(_mix_py((int(seed) * 0x9E3779B97F4A7C15 + 0x2545F4914F6CDD1D) & (2 ** 64 - 1)))


def _mix_py(z: int) -> int:
    m = 2 ** 64 - 1
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m
    return z ^ (z >> 31)


@inline
def mix64(z):
    """SplitMix64's output function: a bijective 64-bit hash."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@inline
def photon_rng(key, photon_id):
    """The start of a photon's random stream."""
    return mix64(key + np.uint64(photon_id) * _M1)


@inline
def uniform2(state):
    """(next state, two uniforms in [0, 1) with 32 random bits each): as many bits as float32
    results can use, at half the cost of two 53-bit ones."""
    state = state + _GAMMA
    z = mix64(state)
    return (state, np.float64(np.int64(z >> _S32)) * _UNIT32,
            np.float64(np.int64(z & _LOW32)) * _UNIT32)


# Taylor coefficients of sin and cos, for x in [−π/4, π/4] (truncation error < 1e-10)
_SIN = (-1 / 6, 1 / 120, -1 / 5040, 1 / 362880, -1 / 39916800)
_COS = (-1 / 2, 1 / 24, -1 / 720, 1 / 40320, -1 / 3628800)


@inline
def _sincos_octant(x):
    """(cos x, sin x) for |x| ≤ π/4, to about 1e-10."""
    x2 = x * x
    s3, s5, s7, s9, s11 = _SIN
    c2, c4, c6, c8, c10 = _COS
    s = x * (1.0 + x2 * (s3 + x2 * (s5 + x2 * (s7 + x2 * (s9 + x2 * s11)))))
    c = 1.0 + x2 * (c2 + x2 * (c4 + x2 * (c6 + x2 * (c8 + x2 * c10))))
    return c, s


@inline
def sincos_2pi(u):
    """(cos 2πu, sin 2πu) for u ≥ −1, to about 1e-10 and several times faster than libm: the
    nearest quarter turn, then Taylor series over the remaining ±π/4."""
    t = 4.0 * u
    k = np.int64(t + 4.5)  # the nearest quarter turn, + 4 (u ≥ −1 keeps it positive)
    c, s = _sincos_octant((t - np.float64(k - 4)) * (0.5 * math.pi))
    k = k & 3  # quarter turns: (cos, sin) of 0, 90, 180, 270 degrees
    cq = np.float64((1 - (k & 1)) * (1 - (k & 2)))
    sq = np.float64((k & 1) * (1 - (k & 2)))
    return c * cq - s * sq, s * cq + c * sq


@inline
def orthonormal_basis(nx, ny, nz):
    """Two unit tangents of a unit normal, branch-free (Duff et al. 2017)."""
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@inline
def in_frame(lx, ly, lz, t, s, n):
    """A direction given in the frame (tangent t, tangent s, normal n), in world space."""
    return (lx * t[0] + ly * s[0] + lz * n[0],
            lx * t[1] + ly * s[1] + lz * n[1],
            lx * t[2] + ly * s[2] + lz * n[2])


@inline
def cosine_lobe(u1, u2):
    """Cosine-weighted direction about +z: (x, y, z)."""
    r = math.sqrt(u1)
    c, s = sincos_2pi(u2)
    return r * c, r * s, math.sqrt(max(0.0, 1.0 - u1))


@inline
def cosine_hemisphere(nx, ny, nz, u1, u2):
    """Cosine-weighted direction about the unit normal n."""
    t, s = orthonormal_basis(nx, ny, nz)
    lx, ly, lz = cosine_lobe(u1, u2)
    return in_frame(lx, ly, lz, t, s, (nx, ny, nz))


@inline
def uniform_sphere(u1, u2):
    z = 1.0 - 2.0 * u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    c, s = sincos_2pi(u2)
    return r * c, r * s, z


@inline
def cone_lobe(cos_max, u1, u2):
    """Direction uniform in solid angle within acos(cos_max) of +z: (x, y, z)."""
    cos_t = 1.0 - u1 * (1.0 - cos_max)
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    c, s = sincos_2pi(u2)
    return sin_t * c, sin_t * s, cos_t


@inline
def uniform_disc(u1, u2):
    """Point uniform on the unit disc (concentric map, area preserving)."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) > abs(b):
        r, x = a, (0.25 * math.pi) * (b / a)
        c, s = _sincos_octant(x)
    else:
        r, x = b, (0.25 * math.pi) * (a / b)
        s, c = _sincos_octant(x)  # the angle is π/2 − x
    return r * c, r * s


@inline
def search_cdf(cdf, u):
    """The first index whose cumulative probability exceeds u (binary search)."""
    lo, hi = 0, cdf.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if cdf[mid] <= u:
            lo = mid + 1
        else:
            hi = mid
    return lo


@inline
def uniform_triangle(u1, u2):
    """Barycentric weights uniform over a triangle."""
    su = math.sqrt(u1)
    b0 = 1.0 - su
    b1 = u2 * su
    return b0, b1, 1.0 - b0 - b1
