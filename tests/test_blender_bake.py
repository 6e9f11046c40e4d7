"""End to end through the bpy wheel: export, energy balance, Cycles' own bake as the reference,
determinism, and the material round trip."""
import filecmp

import numpy as np
import pytest

from conftest import CORNELL
from blender_helpers import export, plane_object, principled, relative_rmse, scene_snapshot, sky_world
from detp_bake import blender
from detp_bake.run.bake import BakeSettings, bake, compute
from detp_bake.estimators import EstimatorSettings
from detp_bake.transport.photons import PhotonTracer


def test_cornell_box_exports_as_saved(cornell, bpy):
    sc = export(bpy)
    names = [o.name for o in sc.objects]
    assert sorted(names) == sorted(["Floor", "Ceiling", "BackWall", "LeftWall", "RightWall", "ShortBox", "TallBox"])
    assert sc.triangle_count == 5 * 32 + 2 * 12
    assert len(sc.lights) == 1 and np.allclose(sc.lights[0].power, 60.0)
    left = sc.object_named("LeftWall")
    assert np.allclose(sc.albedo[left.triangles], [0.63, 0.065, 0.05], atol=1e-6)
    assert sc.default_bounces == 4
    # The tall box is 1.2 m high and rotated in its object transform: world space is applied.
    tall = sc.positions[sc.object_named("TallBox").triangles]
    assert np.isclose(tall[..., 2].max(), 1.2, atol=1e-6)
    assert np.all(np.isfinite(sc.normals)) and np.allclose(np.linalg.norm(sc.normals, axis=2), 1.0)


def test_energy_balance_on_the_cornell_box(cornell, bpy):
    """Emitted = absorbed + escaped (through the open front) when no bounce limit cuts paths."""
    sc = export(bpy, resolution=48)
    tracer = PhotonTracer(sc, 400_000, bounces=1024, seed=3)
    for _ in tracer.batches():
        pass
    st = tracer.stats
    assert np.allclose(st.truncated, 0.0)
    assert np.allclose(st.absorbed + st.escaped, st.emitted, rtol=0.01)
    assert 0.2 < st.escaped.mean() / st.emitted.mean() < 0.8  # the front really is open


@pytest.mark.parametrize("name, rtol", [("disc_index", 0.01), ("photon_map", 0.04)])
def test_absorbed_flux_from_texels_matches_the_photons(cornell, bpy, name, rtol):
    """∫ E·(1 − ρ) dA over all lightmaps (texel coverage areas) = the flux the photons deposited:
    the energy balance of docs/design.md (Ground truths), absorbed = emitted − escaped, read off the lightmaps."""
    sc = export(bpy, resolution=48)
    r = compute(sc, BakeSettings(estimator=name, photons=1_000_000, bounces=1024,
                                 estimator_settings=EstimatorSettings(k=100, radius_texels=1.0)))
    e = r.value * np.pi
    albedo = sc.albedo[r.texels.triangle]
    absorbed = np.sum(e * (1 - albedo) * r.texels.area[:, None], axis=0)
    st = r.stats
    assert np.allclose(st.absorbed + st.escaped, st.emitted, rtol=0.01)
    # The photon map loses flux at every wall edge and corner (boundary bias): a few per cent.
    assert np.allclose(absorbed, st.emitted - st.escaped, rtol=rtol)


@pytest.fixture(scope="module")
def cornell_reference(bpy):
    """Cycles' own bake of every Cornell box object at 32², 128 spp, in this process."""
    bpy.ops.wm.open_mainfile(filepath=str(CORNELL))
    names = [o.name for o in bpy.context.scene.objects if o.type == "MESH"]
    return blender.cycles_bake(bpy.context.scene, names, resolution=32, samples=128)


@pytest.mark.parametrize("name, direct, mean_tol, rmse_tol", [
    ("disc_index", "photons", 0.03, 0.12), ("photon_map", "photons", 0.05, 0.2),
    ("disc_index", "sampled", 0.02, 0.08), ("photon_map", "sampled", 0.03, 0.1)])
def test_cornell_box_matches_cycles(cornell_reference, cornell, bpy, record_property, name, direct, mean_tol,
                                    rmse_tol):
    sc = export(bpy, resolution=32)
    names = [o.name for o in sc.objects]
    r = compute(sc, BakeSettings(estimator=name, photons=2_000_000, direct=direct,
                                 estimator_settings=EstimatorSettings(k=100)))
    # Compare where both bakers sample the same point: texels whose centre lies on the surface.
    ours = np.concatenate([r.images[n][r.centre_masks[n]] for n in names])
    theirs = np.concatenate([cornell_reference[n][r.centre_masks[n]] for n in names])
    rmse = relative_rmse(ours, theirs, np.ones(len(ours), bool))
    record_property("relative_rmse_vs_cycles", rmse)
    print(f"{name} ({direct} direct) vs Cycles: mean {ours.mean() / theirs.mean() - 1:+.3%}, texel relative RMSE {rmse:.3f}")
    assert abs(ours.mean() / theirs.mean() - 1) < mean_tol
    assert rmse < rmse_tol


@pytest.mark.parametrize("direct", ["photons", "sampled"])
def test_emissive_mesh_and_world_match_cycles(empty_blend, bpy, direct):
    """Calibration of the two emitters docs/design.md (Units) says to check: a two-sided emissive plane and a
    constant world colour, against Cycles' direct-light bake of a receiver."""
    scene = empty_blend
    sky_world(bpy, scene, (0.1, 0.2, 0.3))
    recv = plane_object(bpy, "Receiver", 2.0, (0, 0, 0), material=principled(bpy, "Grey", base=(0.5, 0.5, 0.5)))
    plane_object(bpy, "Emitter", 1.0, (0, 0, 1.0), rotation=(np.pi, 0, 0),
                 material=principled(bpy, "Glow", base=(0, 0, 0), emission=(1, 1, 1), strength=2.0))
    sc = export(bpy, objects=["Receiver"], resolution=16)
    ref = blender.cycles_bake(scene, ["Receiver"], resolution=16, samples=256, bounces=0)
    r = compute(sc, BakeSettings(photons=1_000_000, bounces=0, direct=direct,
                                 estimator_settings=EstimatorSettings(k=400)))
    m = r.centre_masks["Receiver"]
    ours, theirs = r.images["Receiver"][m], ref["Receiver"][m]
    assert np.allclose(ours.mean(axis=0), theirs.mean(axis=0), rtol=0.03)
    assert recv.name == "Receiver"


def test_same_seed_gives_identical_files(cornell, bpy, tmp_path):
    sc = export(bpy, objects=["Floor", "TallBox"], resolution=32)
    settings = BakeSettings(photons=200_000, seed=7, formats=("exr", "png"))
    bake(sc, settings, tmp_path / "a")
    bake(sc, settings, tmp_path / "b")
    for name in ("Floor.texel_histogram.exr", "TallBox.texel_histogram.exr", "Floor.texel_histogram.png"):
        assert filecmp.cmp(tmp_path / "a" / name, tmp_path / "b" / name, shallow=False)
    other = bake(sc, BakeSettings(photons=200_000, seed=8), tmp_path / "c")
    assert not np.array_equal(other.images["Floor"], compute(sc, settings).images["Floor"])


def test_apply_then_revert_restores_materials_exactly(cornell, bpy, tmp_path):
    before = scene_snapshot(bpy)
    sc = export(bpy, resolution=16)
    result = bake(sc, BakeSettings(photons=50_000), tmp_path)
    scene = bpy.context.scene
    objs = blender.apply_all(scene, result.files, None, "texel_histogram")
    floor = scene.objects["Floor"]
    mat = floor.material_slots[0].material
    frame = mat.node_tree.nodes[blender.FRAME_NAME]
    tex = next(n for n in mat.node_tree.nodes if n.parent == frame and n.type == "TEX_IMAGE")
    assert tex.image.size[0] == 16 and tex.image.filepath.endswith("Floor.texel_histogram.exr")
    active = [n for n in mat.node_tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output]
    assert any(n.parent == frame for n in active)
    # "White" is shared by five baked objects: each got its own copy, the original is untouched.
    assert len({o.material_slots[0].material.name for o in objs}) == len(objs)
    assert scene_snapshot(bpy) != before
    for obj in objs:
        assert blender.revert(obj)
    assert scene_snapshot(bpy) == before
    assert not blender.revert(floor)  # nothing left to undo


def _add_light(bpy, kind, **props):
    data = bpy.data.lights.new(kind.lower(), kind)
    for key, value in props.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(kind.lower(), data)
    bpy.context.scene.collection.objects.link(obj)
    return obj


LIGHTS = {
    "point": dict(kind="POINT", energy=200.0, location=(0.3, 0.2, 1.5)),
    "point_radius": dict(kind="POINT", energy=200.0, shadow_soft_size=0.4, use_soft_falloff=False,
                         location=(0.0, 0.0, 1.2)),
    "spot_blend": dict(kind="SPOT", energy=300.0, spot_size=np.radians(70), spot_blend=0.5, location=(0.0, 0.0, 1.5)),
    "sun_oblique": dict(kind="SUN", energy=4.0, rotation=(np.radians(30), 0.0, 0.0)),
    "area_disk": dict(kind="AREA", energy=150.0, shape="DISK", size=1.0, location=(0.0, 0.0, 1.0)),
    "area_rectangle": dict(kind="AREA", energy=150.0, shape="RECTANGLE", size=1.2, size_y=0.4,
                           location=(0.4, 0.0, 0.8), rotation=(0.0, np.radians(20), 0.0)),
}


@pytest.mark.parametrize("direct", ["photons", "sampled"])
@pytest.mark.parametrize("case", LIGHTS)
def test_every_light_type_matches_cycles(empty_blend, bpy, case, direct):
    """Direct light on a receiver plane, ours against Cycles' bake: units and shapes per light type."""
    spec = dict(LIGHTS[case])
    kind = spec.pop("kind")
    location, rotation = spec.pop("location", (0, 0, 0)), spec.pop("rotation", (0, 0, 0))
    light = _add_light(bpy, kind, **spec)
    light.location, light.rotation_euler = location, rotation
    plane_object(bpy, "Receiver", 4.0, (0, 0, 0), material=principled(bpy, "Grey", base=(0.5, 0.5, 0.5)))
    sc = export(bpy, objects=["Receiver"], resolution=32)
    ref = blender.cycles_bake(empty_blend, ["Receiver"], resolution=32, samples=128, bounces=0)["Receiver"]
    r = compute(sc, BakeSettings(photons=1_000_000, bounces=0, direct=direct, direct_samples=64, denoise=False,
                                 estimator_settings=EstimatorSettings(radius_texels=1.0)))
    m = r.centre_masks["Receiver"]
    ours, theirs = r.images["Receiver"][m], ref[m]
    rmse = relative_rmse(ours, theirs, np.ones(len(ours), bool))
    print(f"{case} ({direct}): mean {ours.mean() / theirs.mean() - 1:+.3%}, texel relative RMSE {rmse:.3f}")
    # Shadow rays have no disc blur and no photon noise: they match Cycles far more closely.
    mean_tol, rmse_tol = (0.005, 0.03) if direct == "sampled" else (0.03, 0.12)
    if case == "spot_blend" and bpy.app.version >= (5, 0, 0):
        # Cycles 5 smooths a spot's rim over a zone about 8 % wider than Cycles 4.5 and we do
        # (measured; README, Units): up to 9 % apart on the outermost texels, 3.2 % RMSE here.
        rmse_tol = max(rmse_tol, 0.04)
    assert abs(ours.mean() / theirs.mean() - 1) < mean_tol
    assert rmse < rmse_tol


def test_contact_shadows_and_corners_match_cycles(cornell, bpy):
    """Direct light only (no bounce), shadow rays against Cycles at 64²: over the floor and back
    wall, including the contact shadows where the boxes stand and the corners against the walls
    (the shadow rays start a scale-aware epsilon off the surface: no light leaks under the boxes,
    the corners do not go dark). Both sides sample the area light, so texels differ by noise only."""
    sc = export(bpy, objects=["Floor", "BackWall"], resolution=64)
    ref = blender.cycles_bake(bpy.context.scene, ["Floor", "BackWall"], resolution=64, samples=512,
                                    bounces=0)
    r = compute(sc, BakeSettings(photons=1000, bounces=0, direct_samples=64, denoise=False))
    for name in ("Floor", "BackWall"):
        m = r.centre_masks[name]
        ours, theirs = r.images[name][m][:, 0], ref[name][m][:, 0]
        assert abs(ours.mean() / theirs.mean() - 1) < 0.005, name
        lit = theirs > 0.2 * theirs.max()
        assert np.abs(ours[lit] / theirs[lit] - 1).mean() < 0.025, name
        # Where the light changes fast (shadow edges, contact shadows, corners) there is no bias.
        gy, gx = np.gradient(ref[name][..., 0])
        edge = np.hypot(gx, gy)[m] > 0.05 * theirs.max()
        assert edge.sum() > 50 and abs(ours[edge].sum() / theirs[edge].sum() - 1) < 0.01, name
