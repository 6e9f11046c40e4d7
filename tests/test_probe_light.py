"""Probe light on a moving object in Blender (blender/probe_light.py): the SH L2 node group against
sh9.irradiance, rendered; the object's SH following a frame change; Revert restoring the material
exactly; the viewport's probe spheres (blender/probe_view.py)."""
import numpy as np
import pytest

from blender_helpers import node_tree_snapshot, scene_snapshot
from detp_bake.probes import grid, lookup, sh9

SIZE = 48  # pixels of the orthographic render of the unit sphere
BASE = (0.5, 0.8, 0.25)


def _grid():
    """Two probes along x over the box [−2, 2] × [−1, 1] × [−1, 1]: a sun from (0.3, −0.5, 0.8)
    plus a blue sky at x = −1, a dim grey at x = +1."""
    g = grid.ProbeGrid.full("box", np.diag([2.0, 1.0, 1.0, 1.0]), (2, 1, 1))
    sun = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    g.coefficients[0] = sh9.project(sun[None], np.array([[3.0, 2.5, 2.0]])) + sh9.uniform([0.1, 0.2, 0.4])
    g.coefficients[1] = sh9.uniform([0.05, 0.05, 0.05])
    return g


def _sphere_scene(bpy, tmp_path, shared=False):
    """A UV sphere with a Principled material (another object sharing it when `shared`), an
    orthographic camera looking down −z, and probes.npz written in tmp_path."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    mat = bpy.data.materials.new("Paint")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*BASE, 1.0)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=1.0, location=(-1.0, 0.0, 0.0))
    ball = bpy.context.active_object
    ball.name = "Ball"
    bpy.ops.object.shade_smooth()
    ball.data.materials.append(mat)
    if shared:
        bpy.ops.mesh.primitive_cube_add(location=(5, 5, 5))
        bpy.context.active_object.data.materials.append(mat)
    grid.save([_grid()], tmp_path / grid.FILE_NAME)
    return scene, ball, mat


def test_sh_group_renders_the_probe_irradiance(bpy, tmp_path):
    from detp_bake.blender import probe_light
    scene, ball, mat = _sphere_scene(bpy, tmp_path)
    probe_light.apply_probes(scene, tmp_path / grid.FILE_NAME, [ball])
    g = _grid()
    expected_sh = lookup.at([g], [-1.0, 0.0, 0.0])[0]
    np.testing.assert_allclose(np.array([ball[f"detp_probe_sh{k}"][:] for k in range(9)]), expected_sh, rtol=1e-6)
    # Cycles renders the frame's EEVEE output when it is made an output for all engines.
    out = next(n for n in mat.node_tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output)
    assert out.target == "EEVEE"
    out.target = "ALL"
    for n in mat.node_tree.nodes:
        if n.type == "OUTPUT_MATERIAL" and n is not out:
            n.target = "CYCLES"
            n.is_active_output = False
    out.is_active_output = True
    image = _render(bpy, scene, tmp_path, centre=(-1.0, 0.0))
    c = (np.arange(SIZE) + 0.5) / SIZE * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)  # image rows from the top
    r2 = x * x + y * y
    inside = r2 < 0.8 ** 2
    normals = np.stack([x, y, np.sqrt(np.clip(1 - r2, 0, 1))], axis=-1)[inside]
    truth = sh9.irradiance(expected_sh, normals) * np.array(BASE)
    got = image[inside][:, :3]
    # the mesh's smooth normals are within 0.2° of the sphere's: well under 1 % of the light
    np.testing.assert_allclose(got, truth, rtol=0.01, atol=0.003)
    assert got[:, 0].max() > 3 * got[:, 0].min()  # the sun's side is lit: the test can see a wrong SH


def _render(bpy, scene, tmp_path, centre):
    import OpenImageIO as oiio
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.cycles.use_denoising = False
    scene.cycles.pixel_filter_type = "BOX"
    scene.render.filter_size = 0.01
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.world = None
    cam_data = bpy.data.cameras.new("Ortho")
    cam_data.type, cam_data.ortho_scale = "ORTHO", 2.0
    cam = bpy.data.objects.new("Ortho", cam_data)
    cam.location = (centre[0], centre[1], 5.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "render.exr")
    bpy.ops.render.render(write_still=True)
    return oiio.ImageBuf(str(tmp_path / "render.exr")).get_pixels(oiio.FLOAT)


def test_frame_change_moves_the_sh(bpy, tmp_path):
    from detp_bake.blender import probe_light
    scene, ball, mat = _sphere_scene(bpy, tmp_path)
    ball.location = (-1.5, 0.0, 0.0)
    ball.keyframe_insert("location", frame=1)
    ball.location = (1.5, 0.0, 0.0)
    ball.keyframe_insert("location", frame=11)
    scene.frame_set(1)
    probe_light.register_handler()
    try:
        probe_light.apply_probes(scene, tmp_path / grid.FILE_NAME, [ball])
        g = _grid()
        for frame in (1, 6, 11):
            scene.frame_set(frame)
            x = ball.matrix_world.translation.x
            got = np.array([ball[f"detp_probe_sh{k}"][:] for k in range(9)])
            np.testing.assert_allclose(got, lookup.at([g], [x, 0.0, 0.0])[0], rtol=1e-5, atol=1e-7)
        # x = 0 at frame 6: halfway between the two probes
        scene.frame_set(6)
        half = 0.5 * (g.coefficients[0] + g.coefficients[1])
        np.testing.assert_allclose(np.array([ball[f"detp_probe_sh{k}"][:] for k in range(9)]), half, rtol=1e-5)
    finally:
        probe_light.unregister_handler()
    assert probe_light.on_frame_change not in bpy.app.handlers.frame_change_post


@pytest.mark.parametrize("shared", [False, True])
def test_revert_restores_the_material_exactly(bpy, tmp_path, shared):
    from detp_bake import blender
    from detp_bake.blender import probe_light, sh_nodes
    scene, ball, mat = _sphere_scene(bpy, tmp_path, shared=shared)
    before, tree = scene_snapshot(bpy), node_tree_snapshot(mat)
    probe_light.apply_probes(scene, tmp_path / grid.FILE_NAME, [ball])
    shown = ball.material_slots[0].material
    assert (shown is not mat) == shared  # a shared material is copied for the object
    assert probe_light.probe_lit(scene) == [ball]
    assert any(n.type == "GROUP" and n.node_tree.name == sh_nodes.PROBE_GROUP for n in shown.node_tree.nodes)
    assert blender.revert(ball)
    assert node_tree_snapshot(mat) == tree
    assert scene_snapshot(bpy) == before
    assert sh_nodes.PROBE_GROUP not in bpy.data.node_groups
    assert not probe_light.probe_lit(scene)


def test_viewport_spheres_are_coloured_by_the_probes_radiance(bpy):
    from detp_bake.blender import probe_view
    g = _grid()
    g.valid[1] = False
    normals, tris = probe_view.unit_sphere()
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, rtol=1e-12)
    pos, colour, triangles = probe_view.spheres([g], radius=0.1)
    n = len(normals)
    assert pos.shape == (2 * n, 3) and triangles.shape == (2 * len(tris), 3) and triangles.max() == 2 * n - 1
    np.testing.assert_allclose(pos[:n], g.positions[0] + 0.1 * normals, atol=1e-6)
    np.testing.assert_allclose(colour[:n, :3], np.clip(sh9.radiance(g.coefficients[0], normals), 0, None),
                               rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(colour[n:, :3], np.tile(probe_view.INVALID, (n, 1)))  # the invalid probe
    assert colour[:n, 0].max() > 2 * colour[:n, 0].min()  # the sun's side is brighter
    assert probe_view.spacing([g]) == pytest.approx(2.0)


def test_the_panel_applies_probe_light_and_the_toggle_adds_the_draw_handler(bpy, tmp_path):
    from test_addon import _import_addon
    from detp_bake import blender
    from detp_bake.blender import probe_light, probe_view
    module = _import_addon()
    module.register()
    try:
        assert probe_light.on_frame_change in bpy.app.handlers.frame_change_post
        scene, ball, mat = _sphere_scene(bpy, tmp_path)
        scene.detp_bake.output_directory = str(tmp_path)
        ball.detp_bake.probe_light = True
        assert bpy.ops.detp_bake.apply() == {"FINISHED"}
        assert probe_light.probe_lit(scene) == [ball]
        scene.detp_bake.show_probes = True
        assert probe_view.shown() and probe_view.probe_file(scene) == str(tmp_path / grid.FILE_NAME)
        scene.detp_bake.show_probes = False
        assert not probe_view.shown()
        scene.detp_bake.show_probes = True
        assert bpy.ops.detp_bake.revert() == {"FINISHED"} and not probe_light.probe_lit(scene)
        assert blender.REVERT_KEY not in ball
    finally:
        module.unregister()
    assert not probe_view.shown()
    assert probe_light.on_frame_change not in bpy.app.handlers.frame_change_post


def test_the_command_line_lights_objects_marked_in_their_stored_settings(bpy, tmp_path):
    """Without the add-on registered (the command line), the toggle is read from the settings the
    .blend stored on the object."""
    from detp_bake import blender
    scene, ball, mat = _sphere_scene(bpy, tmp_path)
    assert not hasattr(bpy.types.Object, "detp_bake")
    assert blender.apply_marked(scene, tmp_path) == []
    ball["detp_bake"] = {"probe_light": 1}
    assert blender.apply_marked(scene, tmp_path) == [ball]
    assert blender.apply_marked(scene, tmp_path / "elsewhere") == []  # no probes.npz there: nothing
    assert blender.revert(ball)
