"""Direct light over a frame range, re-sampled only where it can change.

A static texel's shadow rays run from the texel to its lights; if none of them can come near a
moving object in any frame of the range (a box per moving object and frame, found when the frames
were evaluated: frames.py), its direct light is the same in every frame and is kept from the first.
Only those texels, and the moving objects' own, are sampled again each frame. They are sampled as
a set of their own, the same set every frame, and each keeps its random numbers from frame to frame
(direct.py draws them per texel, keyed by its object and pixel), so nothing flickers; the first frame samples every texel
once for the rest.

The test is conservative: a shadow ray from x to a light within a sphere (c, r) lies within r of the
segment x–c, so a texel counts as near when that segment passes within r plus a box's half-diagonal
of the box's centre, plus how far from x its rays start (texel_area.spread_reach). A sun is a long
segment towards it, widened by its angle. A world colour, an HDRI or emissive meshes light from
anywhere: then, or when the lights change over the range, every texel is sampled every frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numba
import numpy as np

from . import direct as direct_mod
from ..scene import AreaLight, PointLight, SpotLight, SunLight
from ..lightmap.texel_area import spread_reach
from ..lightmap.texels import of_objects, select


@dataclass
class _Kept:
    key: tuple
    near: np.ndarray  # bool per texel: sampled every frame
    value: np.ndarray  # (N, 3) E of the first frame


def _light_spheres(scene, reach: float) -> Optional[list]:
    """(start offset along -direction or None, centre or direction, radius) per light; None when
    light can come from anywhere (world, HDRI, emissive meshes)."""
    if scene.world_map is not None or np.any(np.asarray(scene.world) != 0) or np.any(scene.emission != 0):
        return None
    out = []
    for light in scene.lights:
        if isinstance(light, (PointLight, SpotLight)):
            out.append((np.asarray(light.position, np.float64), float(light.radius), False))
        elif isinstance(light, AreaLight):
            m = np.asarray(light.matrix, np.float64)
            half = 0.5 * np.hypot(light.size_x * np.linalg.norm(m[:3, 0]), light.size_y * np.linalg.norm(m[:3, 1]))
            out.append((m[:3, 3].copy(), float(half), False))
        elif isinstance(light, SunLight):
            d = np.asarray(light.direction, np.float64)
            d = d / np.linalg.norm(d)
            out.append((-d * reach, reach * np.tan(min(0.5 * float(light.angle), 1.4)), True))
        else:
            return None
    return out


@numba.njit(cache=True, parallel=True)
def _near(pos, slack, light_at, light_r, light_dir, box_c, box_r, out):
    """out[i]: a shadow ray of texel i, starting within slack[i] of it, may pass near one of the boxes
    (spheres box_c, box_r)."""
    for i in numba.prange(pos.shape[0]):
        out[i] = False
        for k in range(light_at.shape[0]):
            ax, ay, az = pos[i, 0], pos[i, 1], pos[i, 2]
            if light_dir[k]:  # a sun: from the texel along the way to it
                bx, by, bz = ax + light_at[k, 0], ay + light_at[k, 1], az + light_at[k, 2]
            else:
                bx, by, bz = light_at[k, 0], light_at[k, 1], light_at[k, 2]
            ux, uy, uz = bx - ax, by - ay, bz - az
            uu = ux * ux + uy * uy + uz * uz
            for b in range(box_c.shape[0]):
                t = 0.0
                if uu > 0.0:
                    t = ((box_c[b, 0] - ax) * ux + (box_c[b, 1] - ay) * uy + (box_c[b, 2] - az) * uz) / uu
                    t = min(max(t, 0.0), 1.0)
                qx, qy, qz = ax + t * ux - box_c[b, 0], ay + t * uy - box_c[b, 1], az + t * uz - box_c[b, 2]
                reach = box_r[b] + light_r[k] + slack[i]
                if qx * qx + qy * qy + qz * qz <= reach * reach:
                    out[i] = True
                    break
            if out[i]:
                break


def _near_texels(state, scene, texels) -> np.ndarray:
    moving = of_objects(texels, state.moving, scene)
    _, radius = scene.bounds()
    lights = _light_spheres(scene, 4.0 * radius)
    if lights is None or state.lights_change or state.moving_boxes is None:
        return np.ones(len(texels), bool)
    if not lights or not len(state.moving_boxes):
        return moving
    boxes = np.asarray(state.moving_boxes, np.float64)
    centre = 0.5 * (boxes[:, 0] + boxes[:, 1])
    half = 0.5 * np.linalg.norm(boxes[:, 1] - boxes[:, 0], axis=1) * (1 + 1e-6) + 1e-6 * radius
    near = np.empty(len(texels), np.bool_)
    _near(np.ascontiguousarray(texels.position), spread_reach(texels, scene), np.array([l[0] for l in lights]),
          np.array([l[1] for l in lights]),
          np.array([l[2] for l in lights]), centre, half, near)
    return near | moving


def direct_irradiance(state, scene, texels, caster, samples, seed, threads, progress=None, cancel=None):
    """direct.direct_irradiance for one frame of a range (`state`: the range's FrameState): the
    first frame samples every texel, later frames only the texels whose direct light can change."""
    _, radius = scene.bounds()
    key = (int(samples), int(seed), radius, texels.pixel.tobytes(), tuple(lm.name for lm in texels.lightmaps))
    kept = state.keep.get("direct")
    first = kept is None or kept.key != key
    if first:
        full, info = direct_mod.direct_irradiance(scene, texels, caster, samples, seed, threads, progress, cancel)
        kept = _Kept(key, _near_texels(state, scene, texels), full)
        state.keep["direct"] = kept
    out = kept.value.copy()
    rows = np.flatnonzero(kept.near)
    if len(rows) < len(texels) or not first:
        part, info_part = direct_mod.direct_irradiance(scene, select(texels, kept.near), caster, samples, seed,
                                                       threads, None if first else progress, cancel)
        out[rows] = part
        if not first:
            info = info_part
        else:
            info = {**info, "rays": info["rays"] + info_part["rays"], "seconds": info["seconds"] + info_part["seconds"]}
    info = {**info, "resampled_texels": int(len(rows)), "reused_texels": int(len(texels) - len(rows))}
    return out, info
