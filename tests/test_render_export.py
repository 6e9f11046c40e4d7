"""What F12 renders is what we bake (issue 8, geometry and lights): the exporter reads Blender's
render evaluation (instances, curves, render-only modifiers and levels, render visibility, ray
visibility), negative lights subtract, and broken light settings stop the bake with a message.
Each Blender case is one small scene compared with Cycles' own bake in the same process."""
import numpy as np
import pytest

from detp_bake.run.bake import BakeSettings, compute
from detp_bake.errors import BakeError
from detp_bake.estimators import EstimatorSettings
from detp_bake.scene import PointLight, SunLight
from synthetic import grid, make_scene


# --------------------------------------------------------------------------- core: negative lights

@pytest.mark.parametrize("direct", ["photons", "sampled"])
def test_negative_light_subtracts_analytically(direct):
    """A point light of power P and one of −P/2 elsewhere: E = E₁ − E₂ at every texel, with the
    photons of the negative light carrying negative flux (or its shadow rays negative irradiance)."""
    h, p = 1.0, 100.0
    a, b = np.array([-0.6, 0.0, h]), np.array([0.7, 0.2, h])
    sc = make_scene([("Plane", grid(4.0, 4.0, 8), 0.0, True)],
                    [PointLight("Plus", a, np.full(3, p)), PointLight("Minus", b, np.full(3, -p / 2))],
                    resolution=32)
    r = compute(sc, BakeSettings(photons=2_000_000, bounces=0, direct=direct, denoise=False,
                                 estimator_settings=EstimatorSettings(radius=0.1)))
    x = r.texels.position

    def e(pos, power):
        d2 = np.sum((x - pos) ** 2, axis=1)
        return power / (4 * np.pi) * h / d2 ** 1.5 / np.pi

    expected = e(a, p) + e(b, -p / 2)
    interior = (np.abs(x[:, 0]) < 1.2) & (np.abs(x[:, 1]) < 1.2)
    ours = r.value[interior, 0]
    assert ours.min() < 0.0  # under the negative light the difference is negative, as in Cycles
    scale = np.abs(expected[interior]).mean()
    assert abs(ours.mean() - expected[interior].mean()) < 0.02 * scale
    assert np.abs(ours - expected[interior]).mean() < 0.06 * scale


def test_photon_counts_follow_absolute_flux():
    from detp_bake.transport import lights
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)],
                    [PointLight("Plus", np.array([0, 0, 1.0]), np.full(3, 30.0)),
                     PointLight("Minus", np.array([0.5, 0, 1.0]), np.full(3, -10.0))])
    em = lights.build_emitters(sc)
    assert [e.name for e in em] == ["Plus", "Minus"] and em[1].flux[0] < 0
    assert list(lights.allocate(em, 1000)) == [750, 250]


@pytest.mark.parametrize("light, message", [
    (PointLight("Lamp", np.zeros(3), np.full(3, np.inf)), "light 'Lamp': power is infinite"),
    (PointLight("Lamp", np.zeros(3), np.array([np.nan, 1, 1])), "light 'Lamp': power is not a number"),
    (PointLight("Lamp", np.zeros(3), np.full(3, 3.4e38)), "light 'Lamp': power 3.4e\\+38 W is absurd"),
    (PointLight("Lamp", np.zeros(3), np.ones(3), radius=np.inf), "light 'Lamp': radius is infinite"),
    (SunLight("Sun", np.array([0, 0, -1.0]), np.ones(3), angle=np.nan), "light 'Sun': angle is not a number"),
    (SunLight("Sun", np.zeros(3), np.ones(3)), "light 'Sun': its direction is zero"),
])
def test_broken_light_is_a_clear_error_before_any_work(light, message):
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)], [light])
    with pytest.raises(BakeError, match=message):
        compute(sc, BakeSettings(photons=1000))


# --------------------------------------------------------------------------- Blender scenes

def _light(bpy, name, kind, location=(0, 0, 0), **props):
    data = bpy.data.lights.new(name, kind)
    for key, value in props.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _box(bpy, name, size, location, collection=None):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = name
    if collection is not None:
        for c in list(obj.users_collection):
            c.objects.unlink(obj)
        collection.objects.link(obj)
    return obj


def _floor(bpy, size=3.0):
    from blender_helpers import plane_object, principled
    return plane_object(bpy, "Floor", size, (0, 0, 0), material=principled(bpy, "Grey", base=(0.5, 0.5, 0.5)))


def _versus_cycles(bpy, settings, samples=32, resolution=32, bounces=0, name="Floor"):
    """Our floor and Cycles' (texels whose centre is on the surface) and the exported scene."""
    from blender_helpers import export
    from detp_bake import blender
    sc = export(bpy, objects=[name], resolution=resolution)
    ref = blender.cycles_bake(bpy.context.scene, [name], resolution=resolution, samples=samples,
                                    bounces=bounces)[name]
    r = compute(sc, settings)
    m = r.centre_masks[name]
    return r.images[name][m][:, 0], ref[m][:, 0], sc


def _shadow_matches(ours, theirs, mean_tol=0.03):
    """Same mean, and dark exactly where Cycles is dark (`lit`, the no-shadow value, is read
    off Cycles' brighter texels, robust to its noise)."""
    lit = np.percentile(theirs, 90)
    dark = theirs < 0.3 * lit
    assert dark.sum() >= 10, "the scene has no shadow to compare"
    assert abs(ours.mean() / theirs.mean() - 1) < mean_tol
    assert ours[dark].mean() < 0.15 * lit
    assert ours[theirs > 0.9 * lit].mean() > 0.9 * lit


SUN_ONLY = BakeSettings(photons=1000, bounces=0, denoise=False)


@pytest.mark.parametrize("direct", ["sampled", "photons"])
def test_collection_instance_casts_a_shadow_like_cycles(empty_blend, bpy, direct):
    """Two Empties instance a collection (linked nowhere in the scene) holding one box: both boxes
    shadow the floor as in Cycles, and their mesh is extracted once."""
    _floor(bpy)
    props = bpy.data.collections.new("Props")
    _box(bpy, "Box", 0.8, (0, 0, 0), collection=props)
    for name, x in (("InstA", -0.7), ("InstB", 0.7)):
        inst = bpy.data.objects.new(name, None)
        inst.instance_type, inst.instance_collection = "COLLECTION", props
        inst.location = (x, 0.1, 1.0)
        empty_blend.collection.objects.link(inst)
    _light(bpy, "Sun", "SUN", energy=3.0)
    settings = SUN_ONLY if direct == "sampled" else BakeSettings(
        photons=300_000, bounces=0, direct="photons", denoise=False,
        estimator_settings=EstimatorSettings(radius_texels=1.0))
    ours, theirs, sc = _versus_cycles(bpy, settings)
    print(f"collection instance ({direct}): ours {ours.mean():.4f}, Cycles {theirs.mean():.4f}, "
          f"unshadowed {np.percentile(theirs, 90):.4f}")
    _shadow_matches(ours, theirs, 0.03 if direct == "sampled" else 0.06)
    st = sc.export_stats
    assert st["instances"] == 2 and st["instanced_triangles"] == 24
    assert st["shared_geometries"] == 2 and st["shared_triangles"] == 2 + 12  # floor, and one box for both
    assert st["bytes_per_triangle"] == 240
    assert [(o.name, o.bake) for o in sc.objects] == [("Floor", True), ("InstA (instances)", False),
                                                      ("InstB (instances)", False)]


def test_geometry_nodes_and_particle_instances_cast_shadows_like_cycles(empty_blend, bpy):
    """Instance on Points (geometry nodes) over a grid's four corners, and a particle system whose
    emitter is not rendered but whose instanced boxes are: all of them shadow the floor."""
    from blender_helpers import plane_object
    _floor(bpy, 4.0)
    carrier = plane_object(bpy, "Carrier", 1.6, (0.8, 0.0, 1.0))
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    n_in, n_out = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    points, place = tree.nodes.new("GeometryNodeMeshToPoints"), tree.nodes.new("GeometryNodeInstanceOnPoints")
    cube = tree.nodes.new("GeometryNodeMeshCube")
    cube.inputs["Size"].default_value = (0.4, 0.4, 0.4)
    tree.links.new(n_in.outputs[0], points.inputs["Mesh"])
    tree.links.new(points.outputs["Points"], place.inputs["Points"])
    tree.links.new(cube.outputs["Mesh"], place.inputs["Instance"])
    tree.links.new(place.outputs["Instances"], n_out.inputs[0])
    carrier.modifiers.new("Scatter", "NODES").node_group = tree
    props = bpy.data.collections.new("Props")
    box = _box(bpy, "Grain", 0.3, (0, 0, 0), collection=props)
    emitter = plane_object(bpy, "Emitter", 1.2, (-1.0, 0.0, 1.2))
    emitter.modifiers.new("Hair", "PARTICLE_SYSTEM")
    ps = emitter.particle_systems[0].settings
    ps.type, ps.count, ps.hair_length = "HAIR", 6, 0.2
    ps.render_type, ps.instance_object, ps.particle_size = "OBJECT", box, 1.0
    emitter.show_instancer_for_render = False
    _light(bpy, "Sun", "SUN", energy=3.0)
    ours, theirs, sc = _versus_cycles(bpy, SUN_ONLY)
    print(f"geometry nodes and particles: ours {ours.mean():.4f}, Cycles {theirs.mean():.4f}")
    _shadow_matches(ours, theirs)
    names = {o.name: o.triangle_count for o in sc.objects}
    assert names["Carrier (instances)"] == 4 * 12 and names["Emitter (instances)"] == 6 * 12
    assert "Emitter" not in names and "Carrier" not in names  # neither renders its own faces
    st = sc.export_stats
    assert st["instances"] == 10 and st["instanced_triangles"] == 120
    # Extracted once each: floor, the carrier's own (empty) mesh, the node cube, the grain box.
    assert st["shared_geometries"] == 4 and st["shared_triangles"] == 2 + 0 + 12 + 12
    # Baking every mesh: neither the carrier (no faces of its own) nor the hidden emitter is baked.
    from blender_helpers import export
    assert [o.name for o in export(bpy).objects if o.bake] == ["Floor"]
    with pytest.raises(BakeError, match="object 'Emitter' is not in the render"):
        export(bpy, objects=["Emitter"])


@pytest.mark.parametrize("scale", [(1.0, 2.0, 0.5), (-1.0, 1.0, 1.0), (0.0, 1.0, 1.0)])
def test_instance_transforms_keep_normals_outward(empty_blend, bpy, scale):
    """Scaled, mirrored and flattened instances: corner normals still point out of the box (they
    go through the inverse transpose); flattened to zero width, only the two faces across it stay."""
    from blender_helpers import export
    _floor(bpy)
    props = bpy.data.collections.new("Props")
    _box(bpy, "Box", 0.8, (0, 0, 0), collection=props)
    inst = bpy.data.objects.new("Inst", None)
    inst.instance_type, inst.instance_collection = "COLLECTION", props
    inst.location, inst.scale, inst.rotation_euler = (0.3, -0.2, 1.0), scale, (0.3, 0.2, 0.1)
    empty_blend.collection.objects.link(inst)
    _light(bpy, "Sun", "SUN")
    sc = export(bpy, objects=["Floor"])
    box = sc.object_named("Inst (instances)").triangles
    p, n = sc.positions[box], sc.normals[box]
    assert np.allclose(np.linalg.norm(n, axis=2), 1.0)
    if scale[0] == 0.0:
        assert len(p) == 4
        return
    outward = p.mean(axis=1) - np.array([0.3, -0.2, 1.0])
    assert np.all(np.einsum("tkj,tj->tk", n, outward) > 0)


def test_only_an_instance_cannot_be_baked(empty_blend, bpy):
    from blender_helpers import export
    _floor(bpy)
    props = bpy.data.collections.new("Props")
    _box(bpy, "Box", 0.8, (0, 0, 0), collection=props)
    inst = bpy.data.objects.new("Inst", None)
    inst.instance_type, inst.instance_collection = "COLLECTION", props
    empty_blend.collection.objects.link(inst)
    _light(bpy, "Sun", "SUN")
    with pytest.raises(BakeError, match="object 'Box' is only an instance \\(in Inst\\).*make it real"):
        export(bpy, objects=["Floor", "Box"])
    with pytest.raises(BakeError, match="object 'Inst' is a empty, not a mesh"):
        export(bpy, objects=["Inst"])


def test_curve_with_bevel_casts_a_shadow_like_cycles(empty_blend, bpy):
    _floor(bpy)
    curve = bpy.data.curves.new("Rail", "CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = 0.25
    spline = curve.splines.new("POLY")
    spline.points.add(1)
    spline.points[0].co = (-1.0, -0.5, 1.0, 1.0)
    spline.points[1].co = (1.0, 0.5, 1.0, 1.0)
    empty_blend.collection.objects.link(bpy.data.objects.new("Rail", curve))
    _light(bpy, "Sun", "SUN", energy=3.0)
    ours, theirs, sc = _versus_cycles(bpy, SUN_ONLY)
    print(f"curve: ours {ours.mean():.4f}, Cycles {theirs.mean():.4f}")
    _shadow_matches(ours, theirs)
    assert sc.object_named("Rail").triangle_count >= 20 and not sc.object_named("Rail").bake


def test_render_only_modifier_and_render_subdivision_level(empty_blend, bpy):
    """An Array copy that only renders shadows the floor, a Subdivision Surface is exported at its
    render level, and a modifier off for render is left off, whatever the viewport shows."""
    _floor(bpy, 4.0)
    box = _box(bpy, "Box", 0.8, (-0.8, 0.0, 1.0))
    sub = box.modifiers.new("Subdivision", "SUBSURF")
    sub.levels, sub.render_levels = 0, 2
    array = box.modifiers.new("Array", "ARRAY")
    array.relative_offset_displace = (2.0, 0.0, 0.0)
    array.show_viewport = False
    viewport_only = box.modifiers.new("Mirror", "MIRROR")
    viewport_only.use_axis = (False, True, False)
    viewport_only.mirror_offset_v = 0.0
    viewport_only.show_render = False
    _light(bpy, "Sun", "SUN", energy=3.0)
    ours, theirs, sc = _versus_cycles(bpy, SUN_ONLY)
    print(f"render-only array: ours {ours.mean():.4f}, Cycles {theirs.mean():.4f}")
    _shadow_matches(ours, theirs)
    # 6 faces, 4² quads each at render level 2, 2 triangles per quad, 2 array copies, no mirror.
    assert sc.object_named("Box").triangle_count == 6 * 16 * 2 * 2


def test_render_visibility_not_viewport_visibility(empty_blend, bpy):
    """Hidden in the viewport (monitor icon, H) but rendered: exported, light included. Disabled in
    renders, in a collection disabled in renders or excluded from the view layer: left out."""
    _floor(bpy, 4.0)
    _box(bpy, "MonitorHidden", 0.7, (-1.0, -1.0, 1.0)).hide_viewport = True
    _box(bpy, "HHidden", 0.7, (1.0, -1.0, 1.0)).hide_set(True)
    _box(bpy, "NotRendered", 0.7, (-1.0, 1.0, 1.0)).hide_render = True
    off = bpy.data.collections.new("OffForRender")
    empty_blend.collection.children.link(off)
    off.hide_render = True
    _box(bpy, "InOffCollection", 0.7, (1.0, 1.0, 1.0), collection=off)
    excluded = bpy.data.collections.new("Excluded")
    empty_blend.collection.children.link(excluded)
    _box(bpy, "InExcluded", 0.7, (0.0, 1.2, 1.0), collection=excluded)
    bpy.context.view_layer.layer_collection.children["Excluded"].exclude = True
    sun = _light(bpy, "Sun", "SUN", energy=3.0)
    sun.hide_viewport = True  # the only light: without it there is nothing to bake
    ours, theirs, sc = _versus_cycles(bpy, SUN_ONLY)
    print(f"visibility: ours {ours.mean():.4f}, Cycles {theirs.mean():.4f}")
    _shadow_matches(ours, theirs)
    names = {o.name for o in sc.objects}
    assert {"MonitorHidden", "HHidden"} <= names
    assert not names & {"NotRendered", "InOffCollection", "InExcluded"}
    assert [l.name for l in sc.lights] == ["Sun"]


def test_ray_visibility_and_holdout_as_cycles_bakes_them(empty_blend, bpy):
    """Shadow rays off: no shadow. Camera or diffuse rays off, or a holdout: the shadow stays (as
    in Cycles' bake). A light with diffuse rays off lights nothing."""
    _floor(bpy, 4.0)
    _box(bpy, "NoShadow", 0.8, (-1.0, 0.0, 1.0)).visible_shadow = False
    _box(bpy, "CameraOff", 0.8, (1.0, 0.0, 1.0)).visible_camera = False
    _box(bpy, "DiffuseOff", 0.8, (0.0, 1.2, 1.0)).visible_diffuse = False
    _box(bpy, "Holdout", 0.8, (0.0, -1.2, 1.0)).is_holdout = True
    _light(bpy, "Sun", "SUN", energy=3.0)
    _light(bpy, "Ignored", "POINT", location=(0, 0, 2), energy=1000.0).visible_diffuse = False
    ours, theirs, sc = _versus_cycles(bpy, SUN_ONLY)
    print(f"ray visibility: ours {ours.mean():.4f}, Cycles {theirs.mean():.4f}")
    _shadow_matches(ours, theirs)
    assert "NoShadow" not in {o.name for o in sc.objects}
    assert [l.name for l in sc.lights] == ["Sun"]
    assert "NoShadow" in sum(sc.export_stats["left_out"].values(), [])
    bpy.data.objects["Floor"].is_holdout = True
    from blender_helpers import export
    with pytest.raises(BakeError, match="object 'Floor' is a holdout"):
        export(bpy, objects=["Floor"])


def test_text_surface_and_metaball_arrive_as_triangles(empty_blend, bpy):
    _floor(bpy)
    text = bpy.data.curves.new("Label", "FONT")
    text.body = "Hi"
    text.extrude = 0.05
    empty_blend.collection.objects.link(bpy.data.objects.new("Label", text))
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(location=(1, 1, 1))
    bpy.context.active_object.name = "Nurbs"
    bpy.ops.object.metaball_add(type="BALL", location=(-1, 1, 1))
    bpy.context.active_object.name = "Blob"
    _light(bpy, "Sun", "SUN")
    from blender_helpers import export
    sc = export(bpy, objects=["Floor"])
    for name in ("Label", "Nurbs", "Blob"):
        obj = sc.object_named(name)
        assert obj.triangle_count > 20 and not obj.bake, name
    assert np.all(np.isfinite(sc.normals))


def test_negative_light_matches_cycles(empty_blend, bpy):
    """A point light and a negative one beside it: Cycles subtracts it, and so do we."""
    _floor(bpy, 4.0)
    _light(bpy, "Plus", "POINT", location=(-0.6, 0.0, 1.5), energy=300.0)
    _light(bpy, "Minus", "POINT", location=(0.8, 0.3, 1.2), energy=-150.0)
    ours, theirs, sc = _versus_cycles(bpy, SUN_ONLY, samples=128)  # Cycles picks one light per sample
    print(f"negative light: ours {ours.mean():.4f}, Cycles {theirs.mean():.4f}, min {ours.min():.4f} "
          f"vs {theirs.min():.4f}")
    assert theirs.min() < 0 and ours.min() < 0
    scale = np.abs(theirs).mean()
    assert abs(ours.mean() - theirs.mean()) < 0.02 * scale
    print(f"mean |ours - Cycles| / mean |Cycles| = {np.abs(ours - theirs).mean() / scale:.4f}")
    assert np.abs(ours - theirs).mean() < 0.03 * scale
    assert sorted(l.power[0] for l in sc.lights) == [-150.0, 300.0]


def test_instanced_light_colour_temperature_nodes_and_exposure_match_cycles(empty_blend, bpy):
    """A point light inside a collection that only an Empty instances (twice, by two Empties), with a
    blackbody temperature, a node tree's Emission colour and strength, and an exposure: each
    channel's mean as in Cycles."""
    _floor(bpy, 4.0)
    lamps = bpy.data.collections.new("Lamps")
    data = bpy.data.lights.new("Bulb", "POINT")
    data.energy, data.exposure = 100.0, 1.0
    data.use_temperature, data.temperature = True, 3500.0
    if bpy.app.version < (5, 0, 0):
        data.use_nodes = True
    else:
        with pytest.warns(DeprecationWarning):
            data.use_nodes = True  # creates the node tree, which Blender 5 always uses
    emission = next(n for n in data.node_tree.nodes if n.type == "EMISSION")
    emission.inputs["Color"].default_value = (0.4, 1.0, 0.7, 1.0)
    emission.inputs["Strength"].default_value = 1.5
    lamps.objects.link(bpy.data.objects.new("Bulb", data))
    for name, x in (("LampA", -0.8), ("LampB", 0.9)):
        inst = bpy.data.objects.new(name, None)
        inst.instance_type, inst.instance_collection = "COLLECTION", lamps
        inst.location = (x, 0.2, 1.2)
        empty_blend.collection.objects.link(inst)
    from blender_helpers import export
    from detp_bake import blender
    sc = export(bpy, objects=["Floor"], resolution=32)
    ref = blender.cycles_bake(empty_blend, ["Floor"], resolution=32, samples=128, bounces=0)["Floor"]
    r = compute(sc, SUN_ONLY)
    m = r.centre_masks["Floor"]
    ours, theirs = r.images["Floor"][m].mean(axis=0), ref[m].mean(axis=0)
    print(f"instanced coloured light: ours {ours}, Cycles {theirs}")
    assert sorted(l.name for l in sc.lights) == ["LampA/Bulb", "LampB/Bulb"]
    assert sc.export_stats["instanced_lights"] == 2
    assert np.allclose(ours, theirs, rtol=0.02)


@pytest.mark.parametrize("setting, value, message", [
    ("energy", float("inf"), "light 'Lamp': power is infinite"),
    ("energy", float("nan"), "light 'Lamp': power is not a number"),
    ("energy", 1e30, "light 'Lamp': power 1e\\+30 W is absurd"),
    ("shadow_soft_size", float("inf"), "light 'Lamp': radius 3.4e\\+38 m is absurd"),
    ("color", (float("nan"), 1.0, 1.0), "light 'Lamp': colour is not a number"),
])
def test_broken_light_setting_is_named_before_any_work(empty_blend, bpy, tmp_path, setting, value, message):
    from blender_helpers import export
    _floor(bpy)
    _light(bpy, "Lamp", "POINT", location=(0, 0, 2), **{setting: value})
    with pytest.raises(BakeError, match=message):
        export(bpy, objects=["Floor"])


def test_infinite_power_fails_the_command_line_and_writes_nothing(empty_blend, bpy, tmp_path, capsys):
    """Issue 8 found a light of infinite power baking black with exit 0: now exit 2, the light and
    the setting named, and no file written."""
    from detp_bake import cli
    _floor(bpy)
    _light(bpy, "Lamp", "POINT", location=(0, 0, 2), energy=float("inf"))
    path = tmp_path / "inf.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    code = cli.main(["bake", str(path), "--out", str(tmp_path / "out"), "--photons", "1000"])
    assert code == 2
    assert "light 'Lamp': power is infinite" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_flattened_geometry_over_the_budget_names_the_biggest(empty_blend, bpy):
    from detp_bake import blender
    _floor(bpy)
    props = bpy.data.collections.new("Props")
    _box(bpy, "Box", 0.3, (0, 0, 0), collection=props)
    for i in range(3):
        inst = bpy.data.objects.new(f"Inst{i}", None)
        inst.instance_type, inst.instance_collection = "COLLECTION", props
        inst.location = (i - 1.0, 0.0, 1.0)
        empty_blend.collection.objects.link(inst)
    _light(bpy, "Sun", "SUN")
    export = blender.export_scene
    sc = export(empty_blend, None, ["Floor"], log=lambda m: None, max_bytes=38 * 240)
    assert sc.triangle_count == 38
    with pytest.raises(BakeError, match="38 triangles.*the biggest: 'Box' ×1 in 'Inst0' \\(12 triangles\\)"):
        export(empty_blend, None, ["Floor"], log=lambda m: None, max_bytes=37 * 240)


def test_export_leaves_the_file_as_it_was(empty_blend, bpy):
    """Nothing the export reads through the render evaluation is left changed: scenes, images,
    render settings, modifier and visibility flags, selection, and no engine stays registered."""
    _floor(bpy)
    box = _box(bpy, "Box", 0.8, (0, 0, 1))
    sub = box.modifiers.new("Subdivision", "SUBSURF")
    sub.levels, sub.render_levels = 1, 2
    box.modifiers.new("Array", "ARRAY").show_viewport = False
    _box(bpy, "Hidden", 0.5, (1, 1, 1)).hide_viewport = True
    _box(bpy, "H", 0.5, (-1, 1, 1)).hide_set(True)
    _light(bpy, "Sun", "SUN")
    scene = bpy.context.scene
    bpy.data.objects["Floor"].data.uv_layers.new(name="Lightmap")

    def snapshot():
        objs = {o.name: (o.hide_viewport, o.hide_render, o.hide_get(), o.select_get(), tuple(o.location),
                         [(m.name, m.show_viewport, m.show_render, getattr(m, "levels", None),
                           getattr(m, "render_levels", None)) for m in o.modifiers]) for o in scene.objects}
        r = scene.render
        return (objs, sorted(s.name for s in bpy.data.scenes), sorted(i.name for i in bpy.data.images),
                (r.engine, r.resolution_x, r.resolution_y, r.resolution_percentage, r.use_compositing,
                 r.use_sequencer), bpy.context.view_layer.objects.active.name,
                sorted((c.name, c.hide_render, c.hide_viewport) for c in bpy.data.collections),
                sorted((m.name, m.users) for m in bpy.data.meshes), len(bpy.data.objects))

    before = snapshot()
    from blender_helpers import export
    sc = export(bpy, objects=["Floor"])
    assert sc.object_named("Box").triangle_count == 6 * 16 * 2 * 2  # render level 2, an array of 2
    assert snapshot() == before
    assert not hasattr(bpy.types, "DETP_BAKE_RENDER_EVALUATION")


def test_export_keeps_the_last_render(empty_blend, bpy, tmp_path):
    """The render evaluation renders a copy of the scene: the user's Render Result is untouched."""
    from blender_helpers import export
    _floor(bpy)
    _light(bpy, "Sun", "SUN")
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0, 0, 5)
    empty_blend.collection.objects.link(cam)
    empty_blend.camera = cam
    r = empty_blend.render
    r.engine, r.resolution_x, r.resolution_y = "CYCLES", 16, 16
    empty_blend.cycles.samples, empty_blend.cycles.device = 1, "CPU"
    bpy.ops.render.render()
    result = bpy.data.images["Render Result"]
    result.save_render(str(tmp_path / "before.exr"))
    export(bpy, objects=["Floor"])
    result.save_render(str(tmp_path / "after.exr"))
    pixels = [np.array(bpy.data.images.load(str(tmp_path / f"{n}.exr")).pixels[:]) for n in ("before", "after")]
    assert pixels[0].mean() > 0 and np.array_equal(*pixels)
    assert [i.name for i in bpy.data.images if i.type == "RENDER_RESULT"] == ["Render Result"]


def test_faceless_and_flattened_meshes_get_no_lightmap_and_say_so(cornell, bpy):
    """Baking every mesh skips one without faces and one a zero scale flattens, naming them in one
    line; naming one of them is a clear error. A flattened box still stands in the light as a sheet."""
    from detp_bake.errors import BakeError
    loose = bpy.data.meshes.new("Loose")
    loose.from_pydata([(0, 0, 0), (1, 0, 0)], [(0, 1)], [])
    cornell.collection.objects.link(bpy.data.objects.new("Loose", loose))
    flat = cornell.objects["ShortBox"].copy()
    flat.data = flat.data.copy()
    flat.name, flat.scale = "Flat", (1.0, 0.0, 1.0)
    cornell.collection.objects.link(flat)
    bpy.context.view_layer.update()
    said = []
    from detp_bake import blender
    sc = blender.export_scene(cornell, None, None, None, 16, said.append)
    assert {o.name for o in sc.objects if o.bake} == {"Floor", "Ceiling", "BackWall", "LeftWall", "RightWall",
                                                      "ShortBox", "TallBox"}
    line = next(m for m in said if m.startswith("no lightmap"))
    assert "'Loose' (no faces" in line and "'Flat' (flattened by a zero scale)" in line
    assert sc.object_named("Flat").triangle_count == 4  # the two faces the flattening keeps
    for name, why in (("Loose", "no faces"), ("Flat", "zero scale")):
        with pytest.raises(BakeError, match=f"'{name}' cannot get a lightmap: .*{why}"):
            blender.export_scene(cornell, None, [name], None, 16, said.append)
