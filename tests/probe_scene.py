"""A small scene for the probes' way out of Blender (tests/test_gltf_probes.py, test_viewer_probes.py):
a floor with a hand-made lightmap, a grid of hand-made probes (sun on the x < 0 half, shade on the
x > 0 half), a ball marked Probe Light at x = −2, and a camera looking along +y; the bake folder
(report.json, the floor's EXR, probes.npz) written by hand, as a bake would."""
import json

import numpy as np

from detp_bake.probes import grid, sh9

BALL = (-2.0, 0.0, 1.0)  # its centre; radius 1
BASE = (0.8, 0.6, 0.4)
CAMERA = (0.0, -9.0, 1.0)  # looking along +y, 50 mm lens on a 36 mm sensor, square frame
SUN = np.array([-0.4, -0.6, 0.7]) / np.linalg.norm([-0.4, -0.6, 0.7])


def probes() -> grid.ProbeGrid:
    """4 × 2 × 1 probes over x ∈ [−4, 4], y ∈ [−2, 2], z ∈ [0, 2]: the two x < 0 columns in the sun
    (a sun of irradiance 2.5 from SUN plus a pale sky), the two x > 0 columns in shade (the sky
    only, dimmer)."""
    g = grid.ProbeGrid.full("Probes", np.diag([4.0, 2.0, 1.0, 1.0]) + np.array(
        [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1.0], [0, 0, 0, 0]]), (4, 2, 1))
    sunny = sh9.project(SUN[None], np.array([[2.5, 2.3, 2.0]])) + sh9.uniform([0.15, 0.2, 0.3])
    shade = sh9.uniform([0.08, 0.1, 0.14]) + 0.3 * sh9.project(np.array([[0.0, 0.0, 1.0]]), np.array([[0.1] * 3]))
    g.coefficients[:] = np.where((g.index[:, 0] < 2)[:, None, None], sunny, shade)
    return g


def build(bpy, folder):
    """The scene in the open (empty) file and its bake folder; returns (scene, ball)."""
    import OpenImageIO as oiio
    from detp_bake.blender import probe_light
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    folder.mkdir(parents=True, exist_ok=True)
    ground = bpy.data.materials.new("Ground")
    if bpy.app.version < (5, 0, 0):
        ground.use_nodes = True
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0, 0, 0))
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.scale = (8.0, 4.0, 1.0)
    floor.data.materials.append(ground)
    floor.data.uv_layers.new(name="Lightmap")
    exr = folder / "Floor.texel_histogram.exr"
    pixels = np.zeros((4, 8, 3), np.float32)
    pixels[:, :4], pixels[:, 4:] = 1.2, 0.12  # sunlit and shaded halves
    out = oiio.ImageOutput.create(str(exr))
    out.open(str(exr), oiio.ImageSpec(8, 4, 3, "float"))
    out.write_image(pixels)
    out.close()
    (folder / "report.json").write_text(json.dumps({
        "settings": {"estimator": "texel_histogram"}, "objects": [{"name": "Floor", "files": [str(exr)]}]}))
    grid.save([probes()], folder / grid.FILE_NAME)
    paint = bpy.data.materials.new("Paint")
    if bpy.app.version < (5, 0, 0):
        paint.use_nodes = True
    paint.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*BASE, 1.0)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=1.0, location=BALL)
    ball = bpy.context.active_object
    ball.name = "Ball"
    bpy.ops.object.shade_smooth()
    ball.data.materials.append(paint)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = CAMERA
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x = scene.render.resolution_y = 160
    probe_light.apply_probes(scene, folder / grid.FILE_NAME, [ball])
    return scene, ball
