"""The command line under stress, second battery: meshes with vertices that are not numbers and
faces of no area, noise a small bake cannot measure, stale temporaries of a killed bake, and a
lightmaps folder of another scene given to export-gltf. Each case ends in a clear outcome that
names the object and the reason."""
import json
import math

import numpy as np
import pytest

from detp_bake.cli import main


def _files(folder):
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def _mesh(bpy, name, verts, faces):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _ground_scene(bpy, path, extra=()):
    """A ground lit by a point light, and the meshes `extra` ((name, verts, faces), ...); saved."""
    from blender_helpers import plane_object
    bpy.ops.wm.read_factory_settings(use_empty=True)
    plane_object(bpy, "Ground", 4.0, (0, 0, 0))
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 2))
    bpy.context.active_object.data.energy = 200.0
    for name, verts, faces in extra:
        _mesh(bpy, name, verts, faces)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


QUAD = [(-0.5, -0.5, 1.0), (0.5, -0.5, 1.0), (0.5, 0.5, 1.0), (-0.5, 0.5, 1.0)]


@pytest.mark.parametrize("bad", [math.nan, math.inf], ids=["nan", "inf"])
def test_a_vertex_that_is_not_a_number_is_named_not_dropped_in_silence(tmp_path, capsys, bpy, bad):
    """Named with --objects: refused before any work, nothing written. Baking all: skipped with a
    warning naming it and the count, on stderr and in report.json; the ground still bakes."""
    quad = [(bad, -0.5, 1.0), *QUAD[1:]]
    path = _ground_scene(bpy, tmp_path / "nan.blend", [("Quad", quad, [(0, 1, 2, 3)])])
    out = tmp_path / "out"
    common = ["bake", str(path), "--photons", "20000", "--resolution", "16", "--out", str(out)]
    assert main([*common, "--objects", "Quad"]) == 2
    err = capsys.readouterr().err
    assert ("detp_bake: error: object 'Quad' cannot get a lightmap: 1 of its 4 vertices is not finite "
            "(NaN or infinite coordinates)") in err
    assert "Tracing" not in err and _files(out) == []

    assert main(common) == 0
    err = capsys.readouterr().err
    warning = "no lightmap for 'Quad' (1 of its 4 vertices is not finite (NaN or infinite coordinates)"
    assert f"detp_bake: warning: {warning}" in err and "baking 1 objects" in err
    report = json.loads((out / "report.json").read_text())
    assert any(warning in w for w in report["warnings"])
    assert [o["name"] for o in report["objects"]] == ["Ground"]


def test_faces_of_zero_area_neither_crash_nor_make_nans(tmp_path, capsys, bpy):
    """A quad with a zero-area triangle beside it bakes finite values; a mesh whose faces all have
    no area gets no lightmap, said as a warning (all baked) or an error (named)."""
    from detp_bake.lightmap.images import read_image
    sliver = [*QUAD, (0.0, 0.0, 1.0), (0.2, 0.0, 1.0), (0.4, 0.0, 1.0)]  # three points on a line
    dot = [(1.5, 1.5, 0.5)] * 4
    path = _ground_scene(bpy, tmp_path / "flat.blend", [("Sliver", sliver, [(0, 1, 2, 3), (4, 5, 6)]),
                                                        ("Dot", dot, [(0, 1, 2, 3)])])
    out = tmp_path / "out"
    common = ["bake", str(path), "--photons", "20000", "--resolution", "16", "--out", str(out)]
    assert main(common) == 0
    err = capsys.readouterr().err
    assert "detp_bake: warning: no lightmap for 'Dot': all its faces have zero area" in err
    for name in ("Ground", "Sliver"):
        image = read_image(out / f"{name}.texel_histogram.exr")
        assert np.isfinite(image).all() and image.max() > 0, name
    assert main([*common, "--objects", "Dot"]) == 2
    assert "error: object 'Dot' has no faces to bake: all its faces have zero area" in capsys.readouterr().err
