"""What Cycles shades is what we bake: textured albedo, alpha cut-outs, Transparent BSDF, a 50 % mix,
an HDRI world, emission textures — each against Cycles' own bake of the same file, in-process."""
import numpy as np
import pytest

from blender_helpers import export, plane_object, principled
from detp_bake import blender
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.estimators import EstimatorSettings


def _image(bpy, name, rgba, colorspace="sRGB"):
    """A packed-in-memory image from an (H, W, 4) array (row 0 at the bottom)."""
    rgba = np.asarray(rgba, np.float32)
    img = bpy.data.images.new(name, rgba.shape[1], rgba.shape[0], alpha=True)
    img.colorspace_settings.name = colorspace
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    return img


def _textured(bpy, name, img, alpha=False, interpolation="Closest", diffuse=False):
    """A material whose Base Color (or, with `diffuse`, a Diffuse BSDF's Color) is the image."""
    mat = principled(bpy, name)
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    if diffuse:
        out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
        nt.nodes.remove(bsdf)
        bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
        nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = interpolation
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Color" if diffuse else "Base Color"])
    if alpha:
        nt.links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
    return mat


def _sun(bpy, strength=3.0, rotation=(0, 0, 0)):
    data = bpy.data.lights.new("Sun", "SUN")
    data.energy = strength
    data.angle = 0.0
    obj = bpy.data.objects.new("Sun", data)
    obj.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _ours(bpy, objects, resolution, photons=1_000_000, bounces=None, **kw):
    sc = export(bpy, objects=objects, resolution=resolution)
    return sc, compute(sc, BakeSettings(photons=photons, bounces=bounces, **kw))


def _means(result, ref, name, region):
    """Mean E/π of ours and Cycles' over centre texels of `name` inside `region` (a texel mask
    over the lightmap image)."""
    m = result.centre_masks[name] & region
    return result.images[name][m].mean(axis=0), ref[name][m].mean(axis=0)


def test_a_red_textured_wall_tints_the_floor_as_in_cycles(empty_blend, bpy):
    """A sunlit floor beside a wall whose Base Color is a red image (sRGB): the light the wall
    bounces onto the floor is red. Ours and Cycles agree on the floor's green/red ratio next to the
    wall within a few per cent (untextured grey would give 1.0)."""
    red = np.zeros((8, 8, 4), np.float32)
    red[...] = (0.9, 0.25, 0.2, 1.0)  # sRGB values: linear ≈ (0.79, 0.05, 0.03)
    img = _image(bpy, "Red", red)
    plane_object(bpy, "Floor", 4.0, (0, 0, 0), material=principled(bpy, "Grey", base=(0.5, 0.5, 0.5)))
    # A Diffuse BSDF: Principled adds a glossy coat that mirrors the sun onto the floor (README).
    wall = _textured(bpy, "RedTex", img, diffuse=True)
    plane_object(bpy, "Wall", 4.0, (0, 2.0, 2.0), rotation=(np.pi / 2, 0, 0), material=wall)
    _sun(bpy, 3.0, rotation=(np.radians(50), 0, 0))  # travels towards +y: onto the floor and the wall's front
    sc, r = _ours(bpy, ["Floor"], 64, photons=2_000_000, bounces=1)
    ref = blender.cycles_bake(empty_blend, ["Floor"], resolution=64, samples=256, bounces=1)
    assert sc.textures is not None and (sc.albedo_texture >= 0).any()
    rows = np.arange(64)[:, None] * np.ones(64)[None, :]
    near_wall = rows >= 52  # lightmap rows towards +y (the wall): the last 75 cm
    # Indirect only: subtract the direct part, which is the same grey in both.
    r0 = compute(sc, BakeSettings(photons=2_000, bounces=0))
    ref0 = blender.cycles_bake(empty_blend, ["Floor"], resolution=64, samples=64, bounces=0)
    ours = r.images["Floor"] - r0.images["Floor"]
    theirs = ref["Floor"] - ref0["Floor"]
    m = r.centre_masks["Floor"] & near_wall
    g_r_ours = ours[m][:, 1].mean() / ours[m][:, 0].mean()
    g_r_cycles = theirs[m][:, 1].mean() / theirs[m][:, 0].mean()
    assert g_r_cycles < 0.2  # really red
    assert abs(g_r_ours - g_r_cycles) < 0.03
    # The light rises steeply into the corner: 3-texel discs (6 cm texels) blur it by a few per cent.
    assert abs(ours[m][:, 0].mean() / theirs[m][:, 0].mean() - 1) < 0.06


@pytest.mark.parametrize("card", ["alpha_texture", "transparent_bsdf", "half_mix"])
def test_cards_let_through_what_cycles_lets_through(empty_blend, bpy, card):
    """A card 0.5 m over a floor under a sun straight down: an alpha-cut card (half of it holes),
    a Transparent BSDF card, and a 50 % mix with Transparent. The floor under the card, relative to
    the open floor, matches Cycles within 5 % (of the open floor)."""
    plane_object(bpy, "Floor", 4.0, (0, 0, 0), material=principled(bpy, "Grey", base=(0.5, 0.5, 0.5)))
    if card == "alpha_texture":
        rgba = np.ones((2, 2, 4), np.float32)
        rgba[:, 0, 3] = 0.0  # the left half is a hole
        mat = _textured(bpy, "Leaf", _image(bpy, "LeafAlpha", rgba), alpha=True)
    else:
        mat = principled(bpy, "Card")
        nt = mat.node_tree
        out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
        transparent = nt.nodes.new("ShaderNodeBsdfTransparent")
        if card == "transparent_bsdf":
            nt.links.new(transparent.outputs[0], out.inputs["Surface"])
        else:
            bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
            mix = nt.nodes.new("ShaderNodeMixShader")
            mix.inputs["Fac"].default_value = 0.5
            nt.links.new(transparent.outputs[0], mix.inputs[1])
            nt.links.new(bsdf.outputs[0], mix.inputs[2])
            nt.links.new(mix.outputs[0], out.inputs["Surface"])
    plane_object(bpy, "Card", 1.0, (0, 0, 0.5), material=mat)
    _sun(bpy, 3.0)
    _, r = _ours(bpy, ["Floor"], 32, photons=200_000, bounces=0)
    ref = blender.cycles_bake(empty_blend, ["Floor"], resolution=32, samples=128, bounces=0)
    cols = np.ones(32)[:, None] * np.arange(32)[None, :]
    rows = cols.T
    band = (rows > 13) & (rows < 18)
    open_floor = (rows < 6) | (rows > 25)
    regions = {"hole": band & (cols > 12) & (cols < 15), "solid": band & (cols > 16) & (cols < 19)}
    if card != "alpha_texture":
        regions = {"under": band & (cols > 13) & (cols < 18)}
    full_ours, full_theirs = _means(r, ref, "Floor", open_floor)
    for name, region in regions.items():
        ours, theirs = _means(r, ref, "Floor", region)
        assert abs(ours[0] / full_ours[0] - theirs[0] / full_theirs[0]) < 0.05, (name, ours, theirs)


def _hdri_world(bpy, image, strength=1.0, rotation_z=0.0):
    world = bpy.data.worlds.new("HDRI")
    bpy.context.scene.world = world
    if world.node_tree is None or bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    bg = next(n for n in nt.nodes if n.type == "BACKGROUND")
    bg.inputs["Strength"].default_value = strength
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    coord = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, rotation_z)
    nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    return world


def _sky_image(bpy):
    """A small procedural sky: a bright warm spot (a low sun) and a blue gradient, linear float."""
    h, w = 32, 64
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    sky = np.zeros((h, w, 4), np.float32)
    sky[..., 0] = 0.2 + 0.3 * v[:, None]
    sky[..., 1] = 0.3 + 0.4 * v[:, None]
    sky[..., 2] = 0.6 + 0.6 * v[:, None]
    sky[..., 3] = 1.0
    sky[22:24, 40:42, :3] = (60.0, 50.0, 40.0)
    sky[: h // 2, :, :3] *= 0.3  # darker below the horizon
    del u
    img = bpy.data.images.new("Sky", w, h, float_buffer=True)
    img.pixels.foreach_set(sky.ravel())
    img.pack()
    return img


@pytest.mark.parametrize("rotation_z", [0.0, 1.2])
def test_hdri_world_on_an_open_plane_and_under_an_overhang(empty_blend, bpy, rotation_z):
    plane_object(bpy, "Ground", 4.0, (0, 0, 0), material=principled(bpy, "Grey", base=(0.5, 0.5, 0.5)))
    plane_object(bpy, "Roof", 1.5, (0.0, 0.0, 0.6), material=principled(bpy, "Grey2", base=(0.5, 0.5, 0.5)))
    _hdri_world(bpy, _sky_image(bpy), strength=1.5, rotation_z=rotation_z)
    sc, r = _ours(bpy, ["Ground"], 32, photons=200_000, bounces=0, direct_samples=64)
    ref = blender.cycles_bake(empty_blend, ["Ground"], resolution=32, samples=256, bounces=0)
    assert sc.world_map is not None
    rows, cols = np.mgrid[0:32, 0:32]
    centre = (np.abs(rows - 15.5) < 4) & (np.abs(cols - 15.5) < 4)
    rim = (rows < 4) | (rows > 27) | (cols < 4) | (cols > 27)
    for region, tol in ((rim, 0.02), (centre, 0.05)):
        ours, theirs = _means(r, ref, "Ground", region)
        assert np.allclose(ours, theirs, rtol=tol), (ours, theirs)


def test_emission_texture_emits_what_cycles_emits(empty_blend, bpy):
    """An emissive panel whose Emission Color is a half-black image emits half of what a plain one
    would: the receiver below gets what Cycles gives within 3 %."""
    rgba = np.ones((2, 2, 4), np.float32)
    rgba[:, 0, :3] = 0.0
    img = _image(bpy, "HalfLit", rgba)
    mat = principled(bpy, "Glow", base=(0, 0, 0), emission=(1, 1, 1), strength=4.0)
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"  # Cycles blends 8-bit sRGB texels before decoding them (README)
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Emission Color"])
    plane_object(bpy, "Receiver", 3.0, (0, 0, 0), material=principled(bpy, "Grey", base=(0.5, 0.5, 0.5)))
    plane_object(bpy, "Panel", 1.0, (0, 0, 1.0), rotation=(np.pi, 0, 0), material=mat)
    _, r = _ours(bpy, ["Receiver"], 16, photons=200_000, bounces=0, direct_samples=64)
    ref = blender.cycles_bake(empty_blend, ["Receiver"], resolution=16, samples=256, bounces=0)
    m = r.centre_masks["Receiver"]
    assert np.isclose(r.images["Receiver"][m].mean(), ref["Receiver"][m].mean(), rtol=0.03)
