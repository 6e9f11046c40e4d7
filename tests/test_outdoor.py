"""Outdoors against Cycles, object by object (issue 8): a small open scene under a sun and a sky
world, where every object's mean must match Cycles' own bake.

The scene holds what made the patio's orange trees and the tree's leaves read high: a ground, a
wall with a sunlit and a shaded face, and a crown of 160 small overlapping leaf cards (one chart of
a few texels per leaf, as Lightmap Pack makes them). Two mechanisms, measured on this scene, and
now fixed:
- a DETP disc's slab (discs.py, rule b) as a fixed r/4 took in the photons that landed on a leaf
  lying just in front of the texel's own leaf: +3 % (default bake) and +6-7 % (the paper's mode)
  on the crown; the slab is now cut to the texel's own surface's rise (estimators/rise.py);
- OIDN's energy kept as a plain mean over covered texels, when a leaf's chart is mostly border
  texels that cover slivers of surface: +2.7 % on the crown's direct light; the mean is now
  weighted by texel area (denoise.py).
Cycles' noise on the means is about 0.1 % here at 128 spp (two seeds), ours about 0.3 % (default)
and 0.5 % (paper's mode). 20-60 s per Blender line on 2 cores.
"""
import math

import numpy as np
import pytest

from blender_helpers import export, lambert, sky_world
from detp_bake import blender
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.scene import SunLight
from synthetic import grid, make_scene

SUN_STRENGTH = 3.0
SKY = (0.35, 0.45, 0.6)
LEAVES = 160
RESOLUTION = 64


def test_a_leaf_under_a_leaf_is_in_shade():
    """Two 1 m plates 5 mm apart under a sun straight above, the paper's mode, no bounce: the upper
    one gets E = S, the lower one nothing but its rim (the sun's 0.5° and the disc's reach past the
    upper plate's edge). A lower disc whose slab reaches the upper plate counts the photons that
    landed there as if they had come through."""
    sun = SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, 3.0), angle=np.radians(0.5))
    sc = make_scene([("Upper", grid(1.0, 1.0, 4, z=0.005), 0.5, True),
                     ("Lower", grid(1.0, 1.0, 4, z=0.0), 0.5, True)], [sun], resolution=32)
    r = compute(sc, BakeSettings(photons=400_000, direct="photons", bounces=0, denoise=False))
    upper, lower = (r.images[n][r.centre_masks[n]].mean(axis=1) * np.pi for n in ("Upper", "Lower"))
    print(f"E/S: upper {upper.mean() / 3.0:.3f}, lower {lower.mean() / 3.0:.3f}")
    assert abs(upper.mean() / 3.0 - 1.0) < 0.03
    assert lower.mean() < 0.05 * 3.0


def _mesh_object(bpy, name, verts, faces, material):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(f) for f in faces])
    me.update()
    me.materials.append(material)
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _leaf_cards(seed=3):
    """LEAVES square cards of 0.22 m, random orientations, centres in a ball of 0.55 m at 1.6 m:
    a dense crown in which most leaves lie over others."""
    rng = np.random.default_rng(seed)
    verts, faces = [], []
    centre = np.array([0.8, 0.6, 1.6])
    for k in range(LEAVES):
        while True:
            p = rng.uniform(-1.0, 1.0, 3)
            if p @ p <= 1.0:
                break
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        t = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
        t /= np.linalg.norm(t)
        s = np.cross(n, t)
        c = centre + 0.55 * p
        h = 0.11
        verts += [c - h * t - h * s, c + h * t - h * s, c + h * t + h * s, c - h * t + h * s]
        faces.append((4 * k, 4 * k + 1, 4 * k + 2, 4 * k + 3))
    return verts, faces


def _box(lo, hi):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    verts = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
             (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return verts, faces


def build_garden(bpy):
    """Into the open (empty) file: ground (6 × 6 m), a wall (3 × 0.25 × 1.8 m) and a leaf crown,
    a sun 50° above the horizon and a sky world; 4 diffuse bounces."""
    scene = bpy.context.scene
    _mesh_object(bpy, "Ground", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], [(0, 1, 2, 3)],
                 lambert(bpy, "Soil", (0.45, 0.38, 0.30)))
    _mesh_object(bpy, "Wall", *_box((-1.5, -1.2, 0.0), (1.5, -0.95, 1.8)), lambert(bpy, "Stucco", (0.75, 0.7, 0.62)))
    _mesh_object(bpy, "Crown", *_leaf_cards(), lambert(bpy, "Leaf", (0.25, 0.45, 0.15)))
    # Lightmap UVs of the test's own (Lightmap Pack: a chart per face), so that what is compared with
    # Cycles is the outdoor light on one fixed layout, not the layout the bake would choose.
    from detp_bake.blender import uv
    for name in ("Ground", "Wall", "Crown"):
        uv.lightmap_pack(bpy.data.objects[name], "Lightmap")
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = SUN_STRENGTH
    sun.data.angle = math.radians(0.5)
    sun.rotation_euler = (math.radians(40.0), 0.0, math.radians(150.0))  # 50° above the horizon
    scene.collection.objects.link(sun)
    sky_world(bpy, scene, SKY)
    scene.cycles.diffuse_bounces = 4
    return scene


@pytest.fixture
def garden(empty_blend, bpy):
    return build_garden(bpy)


def _means(images, masks, names):
    return np.array([float(images[n][masks[n]].mean(dtype=np.float64)) for n in names])


@pytest.mark.parametrize("direct, tolerance", [("sampled", 0.02), ("photons", 0.03)])
def test_every_object_matches_cycles_outdoors(garden, bpy, direct, tolerance):
    """Ground, wall and crown, each one mean over the texels Cycles bakes, within 2 % (default
    bake: shadow rays + DETP on indirect light + OIDN) or 3 % (paper's mode: DETP on every
    segment, whose discs blur the sun's shadows through the crown)."""
    names = ["Ground", "Wall", "Crown"]
    sc = export(bpy, objects=names, resolution=RESOLUTION)
    ref = blender.cycles_bake(garden, names, resolution=RESOLUTION, samples=128)
    r = compute(sc, BakeSettings(photons=2_000_000, direct=direct))
    # The texels Cycles bakes: centre on a UV triangle, and not skipped (exactly 0).
    masks = {n: r.centre_masks[n] & (ref[n].max(axis=2) > 0.0) for n in names}
    ours, theirs = _means(r.images, masks, names), _means(ref, masks, names)
    rel = ours / theirs - 1.0
    print(f"{direct}: " + ", ".join(f"{n} {x:+.2%}" for n, x in zip(names, rel)))
    assert np.all(np.abs(rel) < tolerance), dict(zip(names, rel.round(4)))
