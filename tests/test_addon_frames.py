"""The add-on over a frame range: the Bake operator with the panel's Frame Range and per-object
Motion override, and the panels drawing the new properties."""
import json

from conftest import ROOT
from test_addon import RecordingLayout, addon  # noqa: F401  (a fixture)

QUASI_STATIC = ROOT / "sample_scenes" / "quasi_static.blend"


def test_bake_operator_over_a_frame_range(addon, bpy, tmp_path):  # noqa: F811
    bpy.ops.wm.open_mainfile(filepath=str(QUASI_STATIC))
    scene = bpy.context.scene
    s = scene.detp_bake
    s.photons, s.resolution, s.output_directory, s.denoise = 20_000, 16, str(tmp_path), False
    s.estimator, s.use_frame_range = "hybrid", True
    s.frame_start, s.frame_end, s.frame_step = 1, 13, 12
    scene.objects["Table"].detp_bake.motion = "MOVING"
    scene.objects["CeilingLight"].detp_bake.motion = "STATIC"  # not baked: the override says nothing
    scene.frame_set(7)
    assert bpy.ops.detp_bake.bake() == {"FINISHED"}
    frames = json.loads((tmp_path / "report.json").read_text())["frames"]
    assert frames["done"] == [1, 13] and frames["moving"] == ["Table", "Mover"] and frames["found_moving"] == ["Mover"]
    for frame in (1, 13):
        assert (tmp_path / f"Floor.hybrid.{frame:04d}.exr").stat().st_size > 0
    assert scene.frame_current == 7
    assert json.loads(s.last_report)["frames"] == [1, 13]
    assert "detp_bake lightmap" not in scene.objects["Floor"].material_slots[0].material.node_tree.nodes  # step 12
    s.frame_start, s.frame_end, s.frame_step = 2, 3, 1
    assert bpy.ops.detp_bake.bake() == {"FINISHED"}
    nodes = scene.objects["Floor"].material_slots[0].material.node_tree.nodes
    tex = next(n for n in nodes if n.type == "TEX_IMAGE" and n.image is not None and n.image.source == "SEQUENCE")
    assert tex.image_user.frame_start == 2 and tex.image_user.frame_duration == 2

    from detp_bake_addon.ui import panels
    bpy.context.view_layer.objects.active = scene.objects["Table"]
    seen = set()
    for cls in panels.classes:
        if hasattr(cls, "poll") and not cls.poll(bpy.context):
            continue
        log = []
        panel = type("P", (), {"layout": RecordingLayout(bpy, log)})()
        for method in ("draw_header", "draw"):
            if hasattr(cls, method):
                getattr(cls, method)(panel, bpy.context)
        seen |= {entry[1] for entry in log}
    assert {"use_frame_range", "frame_start", "frame_end", "frame_step", "hybrid_moving", "motion"} <= seen
