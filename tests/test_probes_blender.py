"""Light probes through Blender: Light Probe Volumes read from a .blend, the command line's --probes, and
a probe against Cycles' own bake of a tiny diffuse sphere at its place."""
import json

import numpy as np
import pytest

from blender_helpers import export, lambert
from conftest import CORNELL
from detp_bake.cli import main
from detp_bake.probes import grid as grid_mod, sh9
from detp_bake.run.bake import BakeSettings, compute

PROBE = (0.25, 0.3, 0.6)  # in the Cornell box, between the short box and the lamp


def _volume(bpy, name, location, scale, resolution):
    bpy.ops.object.lightprobe_add(type="VOLUME", location=location)
    obj = bpy.context.active_object
    obj.name, obj.scale = name, scale
    obj.data.resolution_x, obj.data.resolution_y, obj.data.resolution_z = resolution
    bpy.context.view_layer.update()
    return obj


def test_light_probe_volumes_are_read_as_grids(cornell, bpy):
    _volume(bpy, "Room Probes", (0.0, 0.0, 1.0), (0.9, 0.8, 0.9), (3, 2, 4))
    hidden = _volume(bpy, "Hidden", (0.0, 0.0, 1.0), (0.5, 0.5, 0.5), (2, 2, 2))
    hidden.hide_render = True
    (volume,) = export(bpy).probe_volumes
    assert volume.name == "Room Probes" and tuple(volume.resolution) == (3, 2, 4)
    g = grid_mod.ProbeGrid.full(volume.name, volume.matrix, volume.resolution)
    # Cell centres of the unit cube under the object's transform: x at ±0.6 and 0, z from 0.325 up.
    assert np.allclose(sorted(set(np.round(g.positions[:, 0], 6))), [-0.6, 0.0, 0.6])
    assert np.allclose(sorted(set(np.round(g.positions[:, 2], 6))), [0.325, 0.775, 1.225, 1.675])
    # What the panel shows before a bake: the volumes' count exactly, an automatic grid's at most.
    from detp_bake.blender.probe_volumes import panel_cost
    from detp_bake.probes import placement
    count, size, exact = panel_cost(bpy.context.scene, bpy.context.view_layer, "volumes", 1.0)
    assert (count, exact) == (24, True) and size == placement.cost([g])[1]
    count, size, exact = panel_cost(bpy.context.scene, bpy.context.view_layer, "auto", 0.5)
    kept = len(placement.grids_for(export(bpy), "auto", 0.5)[0])
    assert not exact and count >= kept > 0 and size > 0


@pytest.mark.parametrize("blend, probe", [("cornell_box", PROBE), ("window_room", (2.3, 1.6, 1.5))])
def test_a_probe_reconstructs_cycles_tiny_sphere(bpy, blend, probe):
    # Cycles bakes a 4 cm diffuse sphere at the probe's place (E/π per texel, the lightmaps' unit);
    # the probe's SH, read at each texel's normal, gives the same within 3 %. The Cornell box, and
    # the window room: sun and sky through three windows, six lamps inside.
    from detp_bake.blender.reference import cycles_bake
    from detp_bake.lightmap import texels as texels_mod
    bpy.ops.wm.open_mainfile(filepath=str(CORNELL.parent / f"{blend}.blend"))
    _volume(bpy, "Probe", probe, (0.05, 0.05, 0.05), (1, 1, 1))
    scene = export(bpy, resolution=32)
    # A probe reads the lightmaps' light one bounce further (a surface it sees holds `bounces`
    # bounces already): with the scene's 4 it read 3 to 5 % over Cycles' sphere; with 12 both agree.
    result = compute(scene, BakeSettings(photons=400_000, bounces=12, probes="volumes", probe_rays=8192,
                                         direct_samples=64))
    (g,) = result.probes
    assert g.valid.all() and np.allclose(g.positions[0], probe)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.02, segments=24, ring_count=12, location=probe)
    sphere = bpy.context.active_object
    sphere.name = "Probe Sphere"
    sphere.data.materials.append(lambert(bpy, "Sphere", base=(0.8, 0.8, 0.8)))
    reference = cycles_bake(bpy.context.scene, ["Probe Sphere"], uv_name="UVMap", resolution=48, samples=512,
                            margin=0, bounces=12)["Probe Sphere"]
    ours = export(bpy, objects=["Probe Sphere"], uv_layer="UVMap", resolution=48)
    tx = texels_mod.rasterise(ours)
    lm = tx.lightmaps[0]
    pixel = tx.pixel[lm.texels]
    cycles = reference.reshape(-1, 3)[pixel]
    normal = tx.normal[lm.texels]
    probe = sh9.irradiance(g.coefficients[0], normal)

    baked = cycles.min(axis=1) > 0  # texels whose centre lies on the sphere's UVs (Cycles bakes only those)
    # Cycles' irradiance by normal, fitted by nine coefficients (least squares): its L2 part, which
    # is all a probe's SH can hold. Read raw, the probe's differs by up to 9 % facing away from the
    # lamp: L2's own ringing (a clamped cosine cut after band 2 reads 1/16 of the light behind it).
    y = sh9.basis(normal[baked]) * sh9.COSINE_OVER_PI
    fitted = np.linalg.lstsq(y, cycles[baked], rcond=None)[0]
    assert np.sqrt(np.mean((y @ fitted - cycles[baked]) ** 2)) < 0.1 * cycles[baked].mean()  # it holds
    axes = np.vstack([np.eye(3), -np.eye(3)])
    ours, theirs = sh9.irradiance(g.coefficients[0], axes), sh9.irradiance(fitted, axes)
    print(f"{blend}: probe against Cycles' sphere (band 2) at six axes: {np.abs(ours / theirs - 1).max():.2%} at most")
    np.testing.assert_allclose(ours, theirs, rtol=0.03)


@pytest.mark.blender
def test_the_command_line_bakes_probes(tmp_path, capsys, bpy):
    out = tmp_path / "auto"
    code = main(["bake", str(CORNELL), "--photons", "20000", "--resolution", "16", "--probes", "auto",
                 "--probe-spacing", "0.5", "--probe-rays", "64", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    (g,) = grid_mod.load(out / "probes.npz")
    assert report["probes"]["count"] == len(g) > 0 and g.name == "auto"
    assert report["probes"]["invalid"] == int((~g.valid).sum()) and "probes" in report["seconds"]
    # A .blend with a Light Probe Volume, baked with --probes volumes.
    bpy.ops.wm.open_mainfile(filepath=str(CORNELL))
    _volume(bpy, "Room Probes", (0.0, 0.0, 1.0), (0.9, 0.9, 0.9), (2, 2, 2))
    blend = tmp_path / "with_volume.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    code = main(["bake", str(blend), "--photons", "20000", "--resolution", "16", "--probes", "volumes",
                 "--probe-rays", "64", "--out", str(tmp_path / "volumes")])
    assert code == 0, capsys.readouterr().err
    (g,) = grid_mod.load(tmp_path / "volumes" / "probes.npz")
    assert g.name == "Room Probes" and g.resolution == (2, 2, 2) and len(g) == 8 and g.valid.all()
    assert np.all(sh9.irradiance(g.coefficients, np.array([0.0, 0.0, 1.0]))[:, 0] > 0)
    code = main(["bake", str(CORNELL), "--photons", "20000", "--probes", "volumes", "--out", str(tmp_path / "x")])
    assert code != 0 and "no Light Probe Volume" in capsys.readouterr().err
    assert not (tmp_path / "x" / "probes.npz").exists()


def test_an_object_lit_by_probes_is_left_out_of_the_bake(cornell, bpy):
    """Probe Light marks an object that moves: it gets no lightmap and its faces are no geometry of
    the bake (its shadow at the frame baked would stay on the floor when it moves away); named with
    --objects it is refused, saying why."""
    from detp_bake.errors import BakeError
    bpy.ops.mesh.primitive_cube_add(size=0.4, location=(0.0, 0.0, 0.4))
    ball = bpy.context.active_object
    ball.name = "Moving"
    before = export(bpy)
    ball["detp_bake"] = {"probe_light": True}
    after = export(bpy)
    assert "Moving" in {o.name for o in before.objects} and "Moving" not in {o.name for o in after.objects}
    assert before.triangle_count - after.triangle_count == 12
    with pytest.raises(BakeError, match="'Moving' has Probe Light on"):
        export(bpy, objects=["Moving"])
