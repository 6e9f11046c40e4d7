"""Directional lightmaps in Blender: Apply shades a `--directional sh` bake against the material's
normal (blender/sh_nodes.py), so a normal-mapped wall under a low sun shows its bumps lit from the
sun's side as Cycles does with the real light, where the plain lightmap shows them flat; Revert
takes all of it away again (nodes, node groups, images).

The applied material is an emission (base colour × shaded lightmap), rendered here by Cycles
through the same nodes (its output's target set to all engines: exact, no noise); one test renders
it in EEVEE, as the viewport shows it. Pixels are sorted into the bumps' lit and shadowed sides by
their shading normal (an emission render of the normal) against the flat wall's cosine.

DETP_BAKE_WRITE_FIGURE=1 also writes docs/images/directional_wall.png (plain lightmap, SH lightmap,
Cycles; 160² each, the lightmap views in EEVEE)."""
import os

import numpy as np
import pytest

from blender_helpers import export, lambert, plane_object, scene_snapshot
from conftest import ROOT
from detp_bake import blender
from detp_bake.blender import sh_nodes
from detp_bake.lightmap import images, sh
from detp_bake.run.bake import BakeSettings, bake

S, ALBEDO, OFF_NORMAL = 3.0, 0.8, np.radians(65.0)  # sun strength, base colour, sun's angle to the wall's normal
# Towards the sun: 65° off the wall's normal (−y), from the left and 30° above the horizon.
TOWARDS = np.cos(OFF_NORMAL) * np.array([0.0, -1.0, 0.0]) + \
    np.sin(OFF_NORMAL) * np.array([-np.cos(np.radians(30)), 0.0, np.sin(np.radians(30))])
FLAT = ALBEDO * S * np.cos(OFF_NORMAL) / np.pi  # what Cycles shows of the wall without its bumps
FIGURE = os.environ.get("DETP_BAKE_WRITE_FIGURE") == "1"


def _detail(bpy, nt, bsdf, kind):
    """Bumps into the BSDF's Normal: a Wave texture's bands or a Brick texture's mortar through a
    Bump node, or a Noise texture's colour (halfway to flat) through a tangent-space Normal Map node."""
    coords = nt.nodes.new("ShaderNodeTexCoord")
    if kind == "bricks":
        bricks = nt.nodes.new("ShaderNodeTexBrick")
        bricks.inputs["Scale"].default_value = 1.6
        bricks.inputs["Mortar Size"].default_value = 0.04
        bricks.inputs["Mortar Smooth"].default_value = 0.6
        bump = nt.nodes.new("ShaderNodeBump")
        bump.invert = True
        bump.inputs["Distance"].default_value = 0.02
        nt.links.new(coords.outputs["UV"], bricks.inputs["Vector"])
        nt.links.new(bricks.outputs["Fac"], bump.inputs["Height"])
        nt.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
        return
    if kind == "bump":
        wave = nt.nodes.new("ShaderNodeTexWave")
        wave.bands_direction = "X"
        wave.inputs["Scale"].default_value = 2.0
        wave.inputs["Distortion"].default_value = 0.0
        bump = nt.nodes.new("ShaderNodeBump")
        bump.inputs["Distance"].default_value = 0.05
        nt.links.new(coords.outputs["UV"], wave.inputs["Vector"])
        nt.links.new(wave.outputs["Fac"], bump.inputs["Height"])
        nt.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
        return
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 3.0
    noise.inputs["Detail"].default_value = 1.0
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["Factor"].default_value = 0.5
    mix.inputs[7].default_value = (0.5, 0.5, 1.0, 1.0)
    normal_map = nt.nodes.new("ShaderNodeNormalMap")
    normal_map.uv_map = "UVMap"
    nt.links.new(coords.outputs["UV"], noise.inputs["Vector"])
    nt.links.new(noise.outputs["Color"], mix.inputs[6])
    nt.links.new(mix.outputs[2], normal_map.inputs["Color"])
    nt.links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])


def _wall(bpy, kind, size):
    """A 2 m wall facing −y with bumps, a low sun (no sky), an orthographic camera facing it."""
    import mathutils
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    mat = lambert(bpy, "Bumpy", base=(ALBEDO,) * 3)
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    _detail(bpy, mat.node_tree, bsdf, kind)
    wall = plane_object(bpy, "Wall", 2.0, (0, 0, 0), rotation=(np.pi / 2, 0, 0), material=mat)
    light = bpy.data.lights.new("Sun", "SUN")
    light.energy, light.angle = S, 0.0
    sun = bpy.data.objects.new("Sun", light)
    sun.rotation_euler = mathutils.Vector(TOWARDS).to_track_quat("Z", "Y").to_euler()
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.type, camera.data.ortho_scale = "ORTHO", 2.0
    camera.location, camera.rotation_euler = (0, -3, 0), (np.pi / 2, 0, 0)
    for obj in (sun, camera):
        scene.collection.objects.link(obj)
    scene.camera = camera
    r = scene.render
    r.engine, r.resolution_x, r.resolution_y, r.resolution_percentage = "CYCLES", size, size, 100
    scene.cycles.samples, scene.cycles.use_denoising, scene.cycles.device = 16, False, "CPU"
    scene.view_settings.view_transform, scene.view_settings.look = "Standard", "None"
    if hasattr(r.image_settings, "media_type"):  # Blender 5
        r.image_settings.media_type = "IMAGE"
    r.image_settings.file_format, r.image_settings.color_depth = "OPEN_EXR", "32"
    bpy.context.view_layer.update()
    return scene, wall, mat


def _render(bpy, scene, path, engine="CYCLES"):
    """The camera's view, linear (H, W, 3), row 0 at the bottom."""
    if engine == "EEVEE":
        ids = [e.identifier for e in scene.render.bl_rna.properties["engine"].enum_items]
        engine = "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in ids else "BLENDER_EEVEE"
    scene.render.engine, scene.render.filepath = engine, str(path)
    bpy.ops.render.render(write_still=True)
    return images.read_image(path)[..., :3]


def _shading_normals(bpy, scene, mat, path):
    """Each pixel's shading normal (world space), from an emission render of the BSDF's Normal input."""
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    active = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output]
    half = nt.nodes.new("ShaderNodeVectorMath")
    half.operation = "MULTIPLY_ADD"
    half.inputs[1].default_value, half.inputs[2].default_value = (0.5,) * 3, (0.5,) * 3
    emit, out = nt.nodes.new("ShaderNodeEmission"), nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(bsdf.inputs["Normal"].links[0].from_socket, half.inputs[0])
    nt.links.new(half.outputs[0], emit.inputs["Color"])
    nt.links.new(emit.outputs[0], out.inputs["Surface"])
    out.is_active_output = True
    try:
        encoded = _render(bpy, scene, path)
    finally:
        for node in (half, emit, out):
            nt.nodes.remove(node)
        for node in active:
            node.is_active_output = True
    n = 2.0 * encoded - 1.0
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _applied(bpy, scene, wall, files, path, engine="CYCLES"):
    """Render the wall as Apply shows it (`files`: the lightmap's files to apply), then Revert."""
    blender.apply_all(scene, {"Wall": files}, "UVMap", "texel_histogram")
    mat = wall.material_slots[0].material
    out = next(n for n in mat.node_tree.nodes if n.type == "OUTPUT_MATERIAL" and n.target == "EEVEE")
    out.target = "ALL" if engine == "CYCLES" else "EEVEE"  # Cycles through the same nodes
    try:
        return _render(bpy, scene, path, engine)
    finally:
        out.target = "EEVEE"
        assert blender.revert(wall)


def _sides(normals):
    """The bumps' sides facing the sun more than the flat wall does (lit) and less (shadowed), two
    pixels in from the image's edge (the pixel filter reaches past the wall there)."""
    gain = normals @ TOWARDS - np.cos(OFF_NORMAL)
    inside = np.zeros(gain.shape, bool)
    inside[2:-2, 2:-2] = True
    return inside & (gain > 0.05), inside & (gain < -0.05)


def _bake(bpy, tmp_path, directional="sh"):
    sc = export(bpy, objects=["Wall"], uv_layer="UVMap", resolution=32)
    return bake(sc, BakeSettings(photons=20_000, bounces=0, directional=directional), tmp_path / "out").files["Wall"]


@pytest.mark.parametrize("kind, directional", [("bump", "sh"), ("normal_map", "sh"), ("bump", "dominant")])
def test_sh_lightmap_lights_the_bumps_from_the_suns_side_like_cycles(empty_blend, bpy, tmp_path, kind, directional):
    """Lit and shadowed sides of the bumps: the applied SH (or dominant-direction) lightmap's mean is
    on the same side of the flat value as Cycles' (real sun) and within 10 % of it (measured: within
    2.5 %); the plain lightmap shows no bumps; Revert leaves the file as it was (no node group, no
    image)."""
    scene, wall, mat = _wall(bpy, kind, 96)
    cycles = _render(bpy, scene, tmp_path / "cycles.exr")[..., 0]
    lit, dark = _sides(_shading_normals(bpy, scene, mat, tmp_path / "normals.exr"))
    assert lit.mean() > 0.05 and dark.mean() > 0.05, "the wall has no bumps to compare"
    files = _bake(bpy, tmp_path, directional)
    before = scene_snapshot(bpy), sorted(g.name for g in bpy.data.node_groups)
    shaded = _applied(bpy, scene, wall, files, tmp_path / "sh.exr")[..., 0]
    assert (scene_snapshot(bpy), sorted(g.name for g in bpy.data.node_groups)) == before
    plain = _applied(bpy, scene, wall, files[:1], tmp_path / "plain.exr")[..., 0]
    for side in (lit, dark):
        ours, theirs = shaded[side].mean(), cycles[side].mean()
        print(f"{kind} {directional}: Cycles {theirs:.4f}, applied {ours:.4f}, plain {plain[side].mean():.4f}, "
              f"flat {FLAT:.4f}")
        assert np.sign(ours - FLAT) == np.sign(theirs - FLAT)
        assert abs(ours / theirs - 1.0) < 0.10
    assert np.allclose(plain[lit | dark], FLAT, rtol=0.01)  # the plain lightmap: no bumps at all
    # The node group is sh.shade: its mean over the wall is the core's for the rendered normals.
    normals = _shading_normals(bpy, scene, mat, tmp_path / "normals2.exr")
    l0 = np.full(normals.shape[:2] + (3,), S * np.cos(OFF_NORMAL) / np.pi)
    core = ALBEDO * sh.shade(l0, l0[..., None] * TOWARDS, np.array([0.0, -1.0, 0.0]), normals)
    inner = (slice(2, -2), slice(2, -2))
    assert abs(shaded[inner].mean() / core[inner + (0,)].mean() - 1.0) < 0.01


def test_eevee_shows_the_sh_lightmap(empty_blend, bpy, tmp_path):
    """EEVEE, as the viewport shows the applied lightmap: the same sides lit and shadowed as Cycles
    with the real sun, within 10 % per side (measured: 1.2 % lit, 0.7 % shadowed)."""
    scene, wall, mat = _wall(bpy, "normal_map", 96)
    cycles = _render(bpy, scene, tmp_path / "cycles.exr")[..., 0]
    lit, dark = _sides(_shading_normals(bpy, scene, mat, tmp_path / "normals.exr"))
    shaded = _applied(bpy, scene, wall, _bake(bpy, tmp_path), tmp_path / "sh.exr", engine="EEVEE")[..., 0]
    for side in (lit, dark):
        ours, theirs = shaded[side].mean(), cycles[side].mean()
        print(f"EEVEE: Cycles {theirs:.4f}, SH lightmap {ours:.4f}, flat {FLAT:.4f}")
        assert np.sign(ours - FLAT) == np.sign(theirs - FLAT)
        assert abs(ours / theirs - 1.0) < 0.10
    if FIGURE:
        _figure(bpy, tmp_path)


def _figure(bpy, tmp_path):
    """docs/images/directional_wall.png: a brick wall (Brick texture → Bump), 160² each: the plain
    lightmap and the SH lightmap in EEVEE, then Cycles with the real sun (64 samples)."""
    scene, wall, _ = _wall(bpy, "bricks", 160)
    scene.cycles.samples = 64
    cycles = _render(bpy, scene, tmp_path / "cycles160.exr")
    files = _bake(bpy, tmp_path)
    views = [_applied(bpy, scene, wall, f, tmp_path / f"{k}160.exr", engine="EEVEE")
             for k, f in (("plain", files[:1]), ("sh", files))]
    images.write_png(ROOT / "docs" / "images" / "directional_wall.png", np.concatenate([*views, cycles], axis=1))


def test_apply_says_what_it_cannot_show_of_a_shadowmask_and_shades_a_dominant_map(empty_blend, bpy, tmp_path):
    """A shadowmask is for engines: Apply shows the lightmap and says so, naming what an engine does
    with the mask. The dominant map (R G B = direction, A = directionality: a file Blender loads)
    goes through its own group, its alpha kept apart from the colour."""
    scene, wall, _ = _wall(bpy, "bump", 16)
    sc = export(bpy, objects=["Wall"], uv_layer="UVMap", resolution=16)
    result = bake(sc, BakeSettings(photons=10_000, bounces=0, directional="dominant", shadowmask=("Sun",)), tmp_path)
    files = result.files["Wall"]
    written = images.read_image(files[1])
    assert files[1].endswith(".dir.exr") and np.array_equal(written, result.l1_images["Wall"])
    import OpenImageIO as oiio
    assert tuple(oiio.ImageInput.open(files[1]).spec().channelnames) == ("R", "G", "B", "A")
    notes = []
    blender.apply_all(scene, {"Wall": files}, "UVMap", "texel_histogram", log=notes.append)
    assert len(notes) == 1 and "EEVEE takes no light nodes" in notes[0] and "times its channel" in notes[0]
    nodes = wall.material_slots[0].material.node_tree.nodes
    assert [n.node_tree.name for n in nodes if n.type == "GROUP"] == [sh_nodes.DOMINANT_GROUP]
    image = bpy.data.images["Wall.texel_histogram.dir"]
    assert image.alpha_mode == "CHANNEL_PACKED" and image.colorspace_settings.is_data
    assert blender.revert(wall)
    assert not bpy.data.node_groups and "Wall.texel_histogram.dir" not in bpy.data.images
