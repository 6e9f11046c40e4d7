"""The extension inside Blender (bpy wheel, background mode): registration, panels, the bake job
with its worker and cancel, apply/revert, compare, unwrap and the `blender -c` command."""
import importlib
import importlib.util
import json
import sys

import numpy as np
import pytest

from blender_helpers import plane_object, scene_snapshot
from conftest import CORNELL, ROOT

PACKAGE = "detp_bake_addon"


def _import_addon():
    """Import the repository root as the add-on package. Its core subpackage is the very
    `detp_bake` the other tests use: numba's on-disk cache records each kernel's module name, so
    one source file must not be compiled under two package names."""
    if PACKAGE in sys.modules:
        return sys.modules[PACKAGE]
    import pkgutil

    import detp_bake
    for info in pkgutil.walk_packages(detp_bake.__path__, "detp_bake."):
        if info.name != "detp_bake.__main__":
            importlib.import_module(info.name)
    for name, module in list(sys.modules.items()):
        if name == "detp_bake" or name.startswith("detp_bake."):
            sys.modules[f"{PACKAGE}.{name}"] = module
    spec = importlib.util.spec_from_file_location(PACKAGE, ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[PACKAGE] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def addon(bpy):
    module = _import_addon()
    module.register()
    yield module
    module.unregister()


def _registered(bpy):
    names = set()
    for base in (bpy.types.Panel, bpy.types.Operator, bpy.types.PropertyGroup, bpy.types.AddonPreferences):
        names |= {c.__name__ for c in base.__subclasses__() if c.__module__.startswith(PACKAGE)
                  and getattr(c, "is_registered", False)}
    return names


def test_register_and_unregister_leave_nothing_behind(bpy):
    module = _import_addon()
    module.register()
    assert hasattr(bpy.types.Scene, "detp_bake") and hasattr(bpy.types.Object, "detp_bake")
    assert hasattr(bpy.ops.detp_bake, "bake") and bpy.ops.detp_bake.bake.get_rna_type()
    assert len(_registered(bpy)) >= 10
    module.unregister()
    assert not hasattr(bpy.types.Scene, "detp_bake") and not hasattr(bpy.types.Object, "detp_bake")
    assert _registered(bpy) == set()
    module.register()  # and again, as Blender does on reload
    module.unregister()


class RecordingLayout:
    """Stands in for UILayout: records what a panel draws and checks every path exists."""

    def __init__(self, bpy, log):
        self.bpy, self.log = bpy, log
        self.use_property_split = False
        self.scale_y = 1.0
        self.active = True

    def _child(self, *args, **kwargs):
        return RecordingLayout(self.bpy, self.log)

    row = column = box = split = _child

    def label(self, text="", **kwargs):
        self.log.append(("label", text))

    def prop(self, data, path, **kwargs):
        assert path in data.bl_rna.properties, f"{data} has no property {path!r}"
        self.log.append(("prop", path))
        if not self.active:
            self.log.append(("greyed", path))

    def operator(self, idname, **kwargs):
        category, name = idname.split(".")
        assert hasattr(getattr(self.bpy.ops, category), name), f"no operator {idname}"
        self.log.append(("operator", idname))

        class Props:
            pass
        return Props()


def test_every_panel_draws_existing_properties_and_operators(addon, cornell, bpy):
    from detp_bake import estimators
    from detp_bake_addon.ui import panels
    bpy.context.view_layer.objects.active = cornell.objects["Floor"]
    s = cornell.detp_bake
    seen = set()
    for estimator in estimators.names():  # the default (texel_histogram) and every other one
        for lightmaps, mode in (("object", "FIXED"), ("object", "DENSITY"), ("atlas", "FIXED")):
            s.estimator, s.resolution_mode, s.radius_mode = estimator, mode, "WORLD" if mode == "DENSITY" else "TEXELS"
            s.lightmaps = lightmaps
            s.last_report = "" if estimator == "disc_index" else json.dumps(
                {"estimator": estimator, "objects": 7, "photons": 10, "segments": 20,
                 "seconds": {"export": 0.1, "trace": 1.0, "estimate": 0.5, "write": 0.1},
                 "charts": {"Floor": {"count": 1, "median_width": 64.0, "border": 0.06},
                            "Arena": {"count": 4000, "median_width": 2.5, "border": 0.8}}})
            for cls in panels.classes:
                if hasattr(cls, "poll") and not cls.poll(bpy.context):
                    continue
                log = []
                cls.draw(type("P", (), {"layout": RecordingLayout(bpy, log)})(), bpy.context)
                seen |= {entry[1] for entry in log}
    assert {"detp_bake.bake", "detp_bake.apply", "detp_bake.revert", "detp_bake.unwrap", "detp_bake.compare",
            "detp_bake.compare_clear", "detp_bake.open_image", "photons", "radius_texels", "radius", "k", "q",
            "kernel", "hybrid_moving", "texel_density", "uv_layer", "include", "density_scale"} <= seen
    # Every bake setting of options.py but the machine's memory budget (a preference) is on a panel.
    from detp_bake import options
    assert {o.name for o in options.OPTIONS} - seen == {"memory_budget_mb"}


def test_the_size_settings_that_do_nothing_in_a_mode_are_greyed_out(addon, cornell, bpy):
    """What the command line refuses outside its mode (--atlas-size without atlases, --resolution with
    them) the panel shows greyed out, read from the same declaration (options.Option.lightmaps)."""
    from detp_bake_addon.ui import panels
    s = cornell.detp_bake
    greyed = {}
    for lightmaps in ("object", "atlas"):
        s.lightmaps, s.resolution_mode = lightmaps, "FIXED"
        log = []
        panels.DETPBAKE_PT_lightmaps.draw(type("P", (), {"layout": RecordingLayout(bpy, log)})(), bpy.context)
        sizes = {"resolution", "texel_density", "atlas_size", "atlas_padding", "atlas_charts"}
        greyed[lightmaps] = {path for kind, path in log if kind == "greyed"} & sizes
        assert {path for kind, path in log if kind == "prop"} >= {"resolution", "atlas_size", "atlas_padding"}
    assert greyed["object"] == {"atlas_size", "atlas_padding", "atlas_charts"}
    assert greyed["atlas"] == {"resolution"}


def _small(scene, out, **extra):
    s = scene.detp_bake
    s.photons, s.resolution, s.output_directory = 20_000, 16, str(out)
    for key, value in extra.items():
        setattr(s, key, value)


def test_bake_operator_bakes_applies_and_reports(addon, cornell, bpy, tmp_path):
    _small(cornell, tmp_path)
    assert bpy.ops.detp_bake.bake() == {"FINISHED"}
    assert (tmp_path / "Floor.texel_histogram.exr").exists() and (tmp_path / "report.json").exists()
    mat = cornell.objects["Floor"].material_slots[0].material
    assert "detp_bake lightmap" in mat.node_tree.nodes
    report = json.loads(cornell.detp_bake.last_report)
    assert report["estimator"] == "texel_histogram" and report["photons"] == 20_000 and report["objects"] == 7
    assert mat.name.startswith("White (Floor")  # White is shared: Floor got its own copy
    assert bpy.ops.detp_bake.revert() == {"FINISHED"}
    mat = cornell.objects["Floor"].material_slots[0].material
    assert mat.name == "White" and "detp_bake lightmap" not in mat.node_tree.nodes
    assert bpy.ops.detp_bake.apply() == {"FINISHED"}  # from the files on disk
    assert "detp_bake lightmap" in cornell.objects["Floor"].material_slots[0].material.node_tree.nodes


def test_a_directional_panel_bake_applies_the_sh_group_and_revert_removes_it(addon, cornell, bpy, tmp_path):
    """Directional SH L1 from the panel: the bake's Apply and the Apply button (report.json's files)
    wire the SH node group into the materials; Revert leaves no group and no L1 image behind."""
    _small(cornell, tmp_path, directional="sh")
    groups = sorted(g.name for g in bpy.data.node_groups)
    assert bpy.ops.detp_bake.bake() == {"FINISHED"}
    assert (tmp_path / "Floor.texel_histogram.L1x.exr").exists()
    for _ in range(2):  # after the bake, then from the files on disk
        nodes = cornell.objects["Floor"].material_slots[0].material.node_tree.nodes
        group = next(n for n in nodes if n.type == "GROUP")
        assert group.node_tree.name == "detp_bake SH" and group.parent.name == "detp_bake lightmap"
        assert bpy.data.images["Floor.texel_histogram.L1x"].colorspace_settings.is_data
        assert bpy.ops.detp_bake.revert() == {"FINISHED"}
        assert sorted(g.name for g in bpy.data.node_groups) == groups
        assert not any(i.name.endswith((".L1x", ".L1y", ".L1z")) for i in bpy.data.images)
        assert bpy.ops.detp_bake.apply() == {"FINISHED"}
    assert bpy.ops.detp_bake.revert() == {"FINISHED"}


def test_bake_operator_refuses_bad_settings_before_work(addon, cornell, bpy, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    _small(cornell, blocker / "out")
    before = scene_snapshot(bpy)
    with pytest.raises(RuntimeError, match="not writable"):
        bpy.ops.detp_bake.bake()
    assert scene_snapshot(bpy) == before


@pytest.mark.parametrize("phase", ["export", "trace", "estimate", "write"])
def test_cancel_at_each_phase_leaves_the_scene_unchanged(addon, empty_blend, bpy, tmp_path, phase):
    """The worker thread path of the modal operator, cancelled in each phase. The scene has no
    Lightmap UV layer, so the export creates one that a cancel must remove again."""
    from detp_bake.run.job import Cancelled, Preview
    from detp_bake_addon.operators.bake import BakeJob
    plane_object(bpy, "Floor", 2.0, (0, 0, 0))
    bpy.ops.object.light_add(type="SUN", location=(0, 0, 3))
    bpy.ops.object.select_all(action="DESELECT")
    _small(empty_blend, tmp_path / "out", estimator="sphere_cache", live_preview_interval=0.1)
    before = scene_snapshot(bpy)
    job = BakeJob(bpy.context)
    job.prepare(bpy.context)
    assert job.created_uv == [("Floor", "Lightmap")]
    core = job.job
    if phase == "export":
        core.cancel()
    else:
        hook = core._progress

        def cancel_in_phase(p):  # on the worker, so the cancel lands in that very phase
            hook(p)
            if p.phase == phase:
                core.cancel()
        core._progress = cancel_in_phase
    core.start()
    while not job.handle(core.poll()):  # the modal operator's timer, without the timer
        core.thread.join(timeout=0.05)
    assert isinstance(job.outcome, Cancelled)
    assert job.outcome.phase == phase or phase == "export"
    reports = []
    assert job.finish(lambda kind, msg: reports.append(msg)) == {"CANCELLED"}
    assert any("cancelled" in m for m in reports)
    assert scene_snapshot(bpy) == before
    assert not [p for p in (tmp_path / "out").iterdir() if p.suffix in (".exr", ".json")]


def test_compare_and_clear_round_trip(addon, cornell, bpy, tmp_path):
    _small(cornell, tmp_path)
    before = scene_snapshot(bpy)
    n_objects = len(bpy.data.objects)
    assert bpy.ops.detp_bake.compare(estimators={"photon_map", "disc_index"}) == {"FINISHED"}
    coll = bpy.data.collections["detp_bake compare"]
    dups = [o for o in coll.objects if o.type == "MESH"]
    labels = [o for o in coll.objects if o.type == "FONT"]
    assert len(dups) == 2 * 7 and len(labels) == 2
    assert all(d.data == cornell.objects[d.name.split(" [")[0]].data for d in dups)  # linked duplicates
    assert "disc_index" in labels[0].data.body + labels[1].data.body
    assert (tmp_path / "compare.png").exists() and (tmp_path / "Floor.photon_map.exr").exists()
    floor_pm = next(d for d in dups if d.name == "Floor [photon_map]")
    mat = floor_pm.material_slots[0].material
    assert mat != cornell.objects["Floor"].material_slots[0].material  # its own material variant
    assert bpy.ops.detp_bake.compare_clear() == {"FINISHED"}
    assert "detp_bake compare" not in bpy.data.collections and len(bpy.data.objects) == n_objects
    assert scene_snapshot(bpy) == before


def test_unwrap_creates_only_the_lightmap_layer(addon, empty_blend, bpy):
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.active_object
    texture_uv = np.empty(len(obj.data.loops) * 2)
    obj.data.uv_layers["UVMap"].uv.foreach_get("vector", texture_uv)
    for method in ("LIGHTMAP_PACK", "XATLAS"):
        assert bpy.ops.detp_bake.unwrap(method=method) == {"FINISHED"}
        assert [l.name for l in obj.data.uv_layers] == ["UVMap", "Lightmap"]
        assert obj.data.uv_layers.active.name == "UVMap"
        after = np.empty_like(texture_uv)
        obj.data.uv_layers["UVMap"].uv.foreach_get("vector", after)
        assert np.array_equal(after, texture_uv)
        uv = np.empty(len(obj.data.loops) * 2)
        obj.data.uv_layers["Lightmap"].uv.foreach_get("vector", uv)
        assert uv.min() >= 0.0 and uv.max() <= 1.0 and np.ptp(uv) > 0.5


def _centre_hits(uvs, res):
    """How many UV triangles strictly contain each texel centre (shared edges do not count)."""
    counts = np.zeros((res, res), int)
    centres = (np.arange(res) + 0.5) / res
    for tri in uvs:
        (ax, ay), (bx, by), (cx, cy) = tri
        det = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if abs(det) < 1e-12:
            continue
        i0, i1 = np.searchsorted(centres, [tri[:, 0].min(), tri[:, 0].max()])
        j0, j1 = np.searchsorted(centres, [tri[:, 1].min(), tri[:, 1].max()])
        px, py = np.meshgrid(centres[i0:i1], centres[j0:j1])
        l1 = ((px - ax) * (cy - ay) - (py - ay) * (cx - ax)) / det
        l2 = ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / det
        inside = (l1 > 1e-6) & (l2 > 1e-6) & (1 - l1 - l2 > 1e-6)
        counts[j0:j1, i0:i1] += inside
    return counts


@pytest.mark.parametrize("method", ["LIGHTMAP_PACK", "XATLAS"])
def test_unwrapped_charts_do_not_overlap(addon, empty_blend, bpy, method):
    from blender_helpers import export
    bpy.ops.mesh.primitive_monkey_add()
    bpy.ops.object.light_add(type="SUN")
    suzanne = bpy.data.objects["Suzanne"]
    bpy.ops.object.select_all(action="DESELECT")
    suzanne.select_set(True)
    bpy.context.view_layer.objects.active = suzanne
    empty_blend.detp_bake.resolution = 64
    assert bpy.ops.detp_bake.unwrap(method=method) == {"FINISHED"}
    sc = export(bpy, objects=["Suzanne"], resolution=64)
    counts = _centre_hits(sc.uvs, 64)
    assert (counts > 0).sum() > 0.2 * 64 * 64  # the charts fill a good part of the map
    if method == "LIGHTMAP_PACK":
        assert counts.max() == 1
    else:
        # Smart UV Project's islands keep each face whole, but a bent quad can fold over itself
        # in UV space (2 texels of ~900 on Suzanne); charts never overlap each other.
        assert (counts > 1).sum() <= 0.01 * (counts > 0).sum()


def test_blender_command_line_handler_bakes_and_compares(addon, cornell, bpy, tmp_path, capsys):
    from detp_bake_addon.operators import cli_command
    code = cli_command.execute(["bake", "--photons", "20000", "--resolution", "16", "--out", str(tmp_path / "b")])
    assert code == 0 and (tmp_path / "b" / "TallBox.texel_histogram.exr").exists()
    code = cli_command.execute(["compare", "--estimators", "photon_map", "disc_index", "--photons", "20000",
                                "--resolution", "16", "--out", str(tmp_path / "c")])
    assert code == 0
    summary = json.loads((tmp_path / "c" / "compare.json").read_text())
    assert summary["estimators"] == ["photon_map", "disc_index"] and 0 < summary["difference_to_first"]["disc_index"] < 1
    assert cli_command.execute(["bake", "--resolution", "0", "--out", str(tmp_path / "d")]) == 2
    assert "resolution" in capsys.readouterr().err


def test_an_instance_selected_says_how_to_bake_it_and_hidden_meshes_that_render_are_baked(addon, cornell, bpy):
    """The Active Object panel explains that an instancer only lights and shadows the bake (make it
    real to bake it); Bake All takes a mesh hidden in the viewport but rendered, not one disabled in
    renders."""
    from detp_bake_addon.operators import common
    from detp_bake_addon.ui import panels
    coll = bpy.data.collections.new("Props")
    empty = bpy.data.objects.new("Props instance", None)
    empty.instance_type, empty.instance_collection = "COLLECTION", coll
    cornell.collection.objects.link(empty)
    bpy.context.view_layer.objects.active = empty
    log = []
    panels.DETPBAKE_PT_object.draw(type("P", (), {"layout": RecordingLayout(bpy, log)})(), bpy.context)
    text = " ".join(t for kind, t in log if kind == "label")
    assert "instancer" in text and "Make Instances Real" in text
    cornell.objects["TallBox"].hide_set(True)  # hidden in the viewport, still rendered
    cornell.objects["ShortBox"].hide_render = True
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    names = {o.name for o in common.bake_targets(bpy.context)}
    assert "TallBox" in names and "ShortBox" not in names and "Floor" in names


def test_compare_and_bake_are_greyed_out_while_a_bake_runs(addon, cornell, bpy):
    """Two bakes at once would share numba's thread pool: while a job runs (the core's lock), or
    waits for its finish on the main thread, neither operator polls."""
    from detp_bake.run import job as job_mod
    from detp_bake_addon.operators import common
    assert bpy.ops.detp_bake.compare.poll() and bpy.ops.detp_bake.bake.poll()
    holder = job_mod.hold("bake")
    try:
        job_mod._running = type("Running", (), {"kind": "bake"})()  # a job, as the lock sees it
        assert not bpy.ops.detp_bake.compare.poll() and not bpy.ops.detp_bake.bake.poll()
        assert "bake is running" in job_mod.busy_message()
    finally:
        job_mod._running = holder
        job_mod.release(holder)
    assert bpy.ops.detp_bake.bake.poll()
    common.ACTIVE = type("Finishing", (), {"kind": "compare"})()
    try:
        assert not bpy.ops.detp_bake.bake.poll()
    finally:
        common.ACTIVE = None


def _preview_pixels(bpy, name):
    img = bpy.data.images[f"detp_bake preview {name}"]
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    return px


def test_live_preview_refines_the_materials_images_and_esc_restores_the_scene(addon, cornell, bpy, tmp_path):
    """A background-mode job through the operator's job: after each batch the Floor's material
    shows the preview image, which changes; Stop and Keep ends it as a finished bake with the
    photons traced; a cancelled job puts every material back."""
    from detp_bake.run import job as job_mod
    from detp_bake.lightmap.images import file_stem  # noqa: F401  (the core the add-on uses)
    from detp_bake_addon.operators.bake import BakeJob
    _small(cornell, tmp_path / "a", photons=500_000, live_preview_interval=0.1)
    before = scene_snapshot(bpy)

    traced = []  # photons of each preview

    def run(stop_after=None, cancel_after=None):
        job = BakeJob(bpy.context, preview=1e-9)
        job.prepare(bpy.context)
        seen, traced[:] = [], []
        for event in job.job.events():
            job.handle([event])
            if isinstance(event, job_mod.Preview):
                mat = cornell.objects["Floor"].material_slots[0].material
                tex = [n for n in mat.node_tree.nodes if n.type == "TEX_IMAGE" and n.parent is not None]
                assert tex and tex[0].image.name == "detp_bake preview Floor"
                seen.append(_preview_pixels(bpy, "Floor"))
                traced.append(event.photons)
                if len(seen) == stop_after:
                    job.job.stop()
                if len(seen) == cancel_after:
                    job.job.cancel()
        return job, seen, job.finish(lambda kind, msg: None)

    job, seen, status = run(cancel_after=2)
    assert status == {"CANCELLED"} and len(seen) == 2 and not np.array_equal(seen[0], seen[1])
    assert scene_snapshot(bpy) == before  # Esc: the preview's materials and images are gone

    job, seen, status = run(stop_after=1)
    assert status == {"FINISHED"}
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    # The worker may trace one more batch before the stop reaches it: the count is what it traced.
    assert report["photons"] == traced[-1] < 500_000 and report["stopped_by"] == "user"
    assert len(report["objects"]) == 7 and all(o["files"] for o in report["objects"])
    assert json.loads(cornell.detp_bake.last_report)["photons"] == traced[-1]
    assert "detp_bake preview Floor" not in bpy.data.images  # the applied lightmap replaced it
    assert bpy.ops.detp_bake.revert() == {"FINISHED"}


CHOICES = [
    {},  # the defaults
    {"estimator": "disc_index", "photons": 250_000, "direct": "photons", "bounces": 2, "radius_texels": 0.0,
     "seed": 7, "resolution": 64, "margin": 4, "k": 300, "q": 0.7, "denoise": False},
    {"estimator": "hybrid", "hybrid_moving": "disc_index", "target_noise": 2.0, "time_limit": 30.0,
     "direct_samples": 64, "indirect_spacing": 2, "radius_texels": 2.5, "kernel": "epanechnikov", "threads": 2},
]


@pytest.mark.parametrize("choices", CHOICES)
def test_the_panel_and_the_command_line_build_the_same_settings(addon, cornell, bpy, choices):
    """The same choices made in the panel (scene properties) and on the command line give equal
    BakeSettings, and every default is the core's own (options.py)."""
    from detp_bake import cli, options
    from detp_bake.run.bake import BakeSettings

    common = sys.modules[f"{PACKAGE}.operators.common"]
    s = bpy.context.scene.detp_bake
    for name, value in choices.items():
        setattr(s, name, value)
    panel = common.bake_settings(bpy.context)
    argv = ["bake", "x.blend", "--out", "o"]
    for name, value in choices.items():
        opt = options.BY_NAME[name]
        argv += [opt.flag if value else "--no-" + name] if opt.kind is bool else [opt.flag, str(value)]
    line = cli.settings_from_args(cli.build_parser().parse_args(argv))
    assert panel == line
    if not choices:
        assert panel == BakeSettings() and panel.estimator_settings.radius_texels is None
    # Every setting is on the scene's panel, but the memory budget, which is a preference of the
    # machine, and the shadowmask, a toggle on each light (the next test).
    assert {o.name for o in options.OPTIONS if not hasattr(s, o.name)} == {"memory_budget_mb", "shadowmask"}
    for name in choices:  # reset for the next case
        s.property_unset(name)


def test_the_lights_shadowmask_toggles_are_the_command_lines_list(addon, cornell, bpy):
    """One Shadowmask toggle per light (object.detp_bake.shadowmask): the lights switched on, in
    name order, are the command line's --shadowmask list; none on, none masked."""
    from detp_bake import cli

    common = sys.modules[f"{PACKAGE}.operators.common"]
    sun = bpy.data.objects.new("A Sun", bpy.data.lights.new("A Sun", "SUN"))
    cornell.collection.objects.link(sun)
    lamp = next(o for o in cornell.objects if o.type == "LIGHT" and o is not sun)
    assert common.bake_settings(bpy.context).shadowmask == ()
    for light in (lamp, sun):
        light.detp_bake.shadowmask = True
    cornell.detp_bake.shadowmask_mode = "overlay"
    panel = common.bake_settings(bpy.context)
    line = cli.settings_from_args(cli.build_parser().parse_args(
        ["bake", "x.blend", "--out", "o", "--shadowmask", "A Sun", lamp.name, "--shadowmask-mode", "overlay"]))
    assert panel == line and panel.shadowmask == ("A Sun", lamp.name)
    lamp.detp_bake.shadowmask = False
    assert common.bake_settings(bpy.context).shadowmask == ("A Sun",)


def test_a_second_panel_bake_keeps_unchanged_lightmaps_and_rebake_all_bakes_them(addon, cornell, bpy, tmp_path):
    """The panel reuses lightmaps as the command line does (incremental.py): a second bake into the
    same folder with nothing changed writes nothing (the files keep their inodes) and applies the
    files it kept; Rebake All bakes every object again."""
    _small(cornell, tmp_path)
    assert bpy.ops.detp_bake.bake() == {"FINISHED"}
    first = {p.name: p.stat().st_ino for p in tmp_path.glob("*.exr")}
    assert bpy.ops.detp_bake.revert() == {"FINISHED"}
    assert bpy.ops.detp_bake.bake() == {"FINISHED"}
    assert {p.name: p.stat().st_ino for p in tmp_path.glob("*.exr")} == first
    report = json.loads(cornell.detp_bake.last_report)
    assert len(report["reused"]) == 7 and "photons" not in report
    assert "detp_bake lightmap" in cornell.objects["Floor"].material_slots[0].material.node_tree.nodes
    panels = sys.modules[f"{PACKAGE}.ui.panels"]
    log = []
    panels.DETPBAKE_PT_stats.draw(type("P", (), {"layout": RecordingLayout(bpy, log)})(), bpy.context)
    cornell.detp_bake.rebake_all = True
    assert bpy.ops.detp_bake.bake() == {"FINISHED"}
    again = {p.name: p.stat().st_ino for p in tmp_path.glob("*.exr")}
    assert set(again) == set(first) and all(again[n] != first[n] for n in first)
    assert json.loads(cornell.detp_bake.last_report)["photons"] == 20_000
