"""Light probes baked from the lightmaps (probes/): closed forms, walls, the shadowmask split, the file."""
import json

import numpy as np
import pytest

from detp_bake.errors import BakeError
from detp_bake.probes import grid as grid_mod, placement, sh9
from detp_bake.run import bake
from detp_bake.run.settings import BakeSettings
from detp_bake.scene import PointLight, ProbeVolume, SunLight
from synthetic import grid, make_scene, sealed_room

AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)


def _volume(name, centre, half, res):
    m = np.eye(4)
    m[:3, :3] = np.diag(half)
    m[:3, 3] = centre
    return ProbeVolume(name, m, res)


def _settings(**kw):
    return BakeSettings(**{"photons": 5000, "denoise": False, "probes": "volumes", "probe_rays": 1024, **kw})


def test_uniform_sky_over_an_open_plane():
    # Sky radiance 1, a 40 m plane of albedo 0.5 and no bounce: the plane reads E/π = 1 everywhere,
    # so a probe 1 m above its middle reads 1 facing up, and facing down 0.5 over the plane's
    # cosine-weighted share of the lower half of its sphere and 1 beyond its edges.
    scene = make_scene([("Plane", grid(40, 40, 4), 0.5, True)], [], world=(1.0, 1.0, 1.0), resolution=16)
    scene.probe_volumes = [_volume("Above", (0.0, 0.0, 1.0), (0.1, 0.1, 0.1), (1, 1, 1))]
    result = bake.compute(scene, _settings())
    (g,) = result.probes
    assert g.valid.all() and not g.offset.any()
    # The share of the lower hemisphere's cosine-weighted directions that meet the plane.
    u = (np.arange(400) + 0.5) / 400
    cos, phi = np.sqrt(u)[:, None], 2 * np.pi * u[None, :]
    sin = np.sqrt(1 - cos ** 2)
    reach = 1.0 / np.maximum(cos, 1e-9)  # distance to z = −1 along the direction, times sin
    inside = (np.abs(sin * np.cos(phi) * reach) < 20) & (np.abs(sin * np.sin(phi) * reach) < 20)
    on_plane = inside.mean()
    up = sh9.irradiance(g.coefficients[0], np.array([0.0, 0.0, 1.0]))
    down = sh9.irradiance(g.coefficients[0], np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(up, 1.0, rtol=0.01)
    np.testing.assert_allclose(down, 0.5 * on_plane + (1 - on_plane), rtol=0.01)
    assert result.probe_info["count"] == 1 and result.probe_info["invalid"] == 0


def test_one_point_light_in_empty_space_is_a_delta_band_by_band():
    # A black plane far below; a point light of intensity I at distance r: c_k = I/r² · Y_k(d),
    # from one shadow ray, exactly (to float32).
    power = np.array([400.0, 200.0, 100.0])
    light = PointLight("Lamp", np.array([1.0, 2.0, 12.0]), power)
    scene = make_scene([("Floor", grid(4, 4, 1), 0.0, True)], [light], resolution=8)
    probe = np.array([0.0, 0.5, 10.0])
    scene.probe_volumes = [_volume("One", probe, (0.1, 0.1, 0.1), (1, 1, 1))]
    (g,) = bake.compute(scene, _settings(probe_rays=64)).probes
    d = light.position - probe
    r2 = d @ d
    expected = sh9.project((d / np.sqrt(r2))[None], (power / (4 * np.pi) / r2)[None])
    for band in (0, 1, 2):
        rows = sh9.BAND_OF == band
        np.testing.assert_allclose(g.coefficients[0][rows], expected[rows], rtol=1e-5, atol=1e-7)


def test_a_sealed_room_lets_no_sun_into_its_probes():
    # Sun and sky outside a closed room: every probe inside reads at most 1 % of a probe in the sun.
    # The ground's texels (9 cm) are about as wide as the walls (6 cm): a probe reads the lightmap as
    # an engine shows it, and a texel much wider than a wall is lit on both sides of it (a 50 cm
    # texel read 0.11 of the sunny probe's 1.98 here, inside a room whose floor showed it too).
    sun = SunLight("Sun", np.array([-0.3, -0.2, -1.0]), np.array([5.0, 5.0, 5.0]))
    scene = sealed_room([sun], world=(0.3, 0.3, 0.3), resolution=64, bounces=2, ground=6.0)
    inside = _volume("Inside", (0.15, -0.08, 1.2), (0.9, 0.9, 1.1), (3, 3, 3))
    outside = _volume("Outside", (2.5, 2.5, 1.0), (0.1, 0.1, 0.1), (1, 1, 1))
    scene.probe_volumes = [inside, outside]
    result = bake.compute(scene, _settings(photons=20000, probe_rays=512))
    g_in, g_out = result.probes
    assert g_in.valid.all() and g_out.valid.all()
    sunny = sh9.irradiance(g_out.coefficients[0], -sun.direction / np.linalg.norm(sun.direction)).max()
    assert sunny > 5.0 / np.pi  # E/π: the sun alone gives 5/π facing it
    reads = sh9.irradiance(g_in.coefficients[:, None], AXES[None]).max()
    assert reads <= 0.01 * sunny, (reads, sunny)


def test_probes_inside_a_wall_are_moved_out_or_marked():
    # A probe in the middle of a closed box sees only back faces: it is moved out through the
    # nearest one (virtual offset) and then sees the sky, or stays marked invalid.
    scene = sealed_room([], world=(1.0, 1.0, 1.0), resolution=16, bounces=0)
    wall = _volume("Wall", (0.15, -1.13, 1.0), (0.5, 0.5, 0.5), (1, 1, 1))  # in the south wall (y −1.14 to −1.08), 1 cm from its outer face; cells 1 m
    scene.probe_volumes = [wall]
    result = bake.compute(scene, _settings(probe_rays=256))
    (g,) = result.probes
    assert result.probe_info["moved"] == 1 and g.valid[0]
    assert 0.1 < np.linalg.norm(g.offset[0]) < 0.12 and g.offset[0, 1] < 0  # out through the nearer face, 0.1 cell beyond
    assert sh9.irradiance(g.coefficients[0], np.array([0.0, 0.0, 1.0]))[0] > 0.5


def test_shadowmask_lights_leave_the_coefficients_for_an_occlusion():
    # A point light on the shadowmask: no direct light in the coefficients; occlusion 1 in its
    # sight, 0 behind a wall.
    light = PointLight("Lamp", np.array([0.0, 0.0, 3.0]), np.array([100.0, 100.0, 100.0]))
    blocker = grid(2, 2, 1, z=2.0)
    scene = make_scene([("Floor", grid(8, 8, 2), 0.0, True), ("Blocker", blocker, 0.0, False)], [light],
                       resolution=8)
    scene.probe_volumes = [_volume("Pair", (0.0, 0.0, 1.0), (6.0, 0.1, 0.1), (2, 1, 1))]  # x = −3 and 3
    masked = bake.compute(scene, _settings(shadowmask=("Lamp",), probe_rays=64)).probes[0]
    assert masked.shadowmask_lights == ("Lamp",)
    np.testing.assert_allclose(masked.occlusion[:, 0], [1.0, 1.0], atol=1e-6)  # beside the blocker
    assert np.abs(masked.coefficients).max() < 1e-6
    scene.probe_volumes = [_volume("Under", (0.0, 0.0, 1.0), (0.1, 0.1, 0.1), (1, 1, 1))]
    under = bake.compute(scene, _settings(shadowmask=("Lamp",), probe_rays=64)).probes[0]
    np.testing.assert_allclose(under.occlusion[:, 0], [0.0], atol=1e-6)
    kept = bake.compute(scene, _settings(shadowmask=("Lamp",), shadowmask_mode="overlay", probe_rays=64)).probes[0]
    assert kept.occlusion[0, 0] == 0.0 and np.abs(kept.coefficients).max() < 1e-6  # in its shadow all the same


def test_an_automatic_grid_keeps_the_probes_near_geometry():
    # Two 4 m planes 6 m apart, spacing 1 m: the box grown by a spacing is 6 × 6 × 8 cells; a probe
    # is kept within 1 m of a plane (measured here by brute force over the full grid).
    low, high = grid(4, 4, 1), grid(4, 4, 1, z=6.0)
    scene = make_scene([("Low", low, 0.5, True), ("High", high, 0.5, True)], [], resolution=8)
    (g,) = placement.grids_for(scene, "auto", 1.0)
    assert g.resolution == (6, 6, 8)
    full = grid_mod.ProbeGrid.full("all", g.matrix, g.resolution).positions
    edge = np.hypot(*np.maximum(np.abs(full[:, :2]) - 2.0, 0.0).T)
    near = np.minimum(np.hypot(edge, full[:, 2]), np.hypot(edge, full[:, 2] - 6.0)) <= 1.0
    assert len(g) == near.sum() == 4 * 36
    assert set(np.round(g.positions[:, 2], 6)) == {-0.5, 0.5, 5.5, 6.5}
    count, size = placement.cost([g])
    assert count == len(g) and size > count * 100
    with pytest.raises(BakeError, match="probe_spacing"):
        placement.grids_for(scene, "auto", 1e-4)
    with pytest.raises(BakeError, match="no Light Probe Volume"):
        placement.grids_for(scene, "volumes", 1.0)


def test_probes_are_written_with_the_lightmaps_and_reported(tmp_path):
    scene = make_scene([("Plane", grid(4, 4, 1), 0.5, True)], [], world=(0.5, 0.5, 0.5), resolution=8)
    result = bake.bake(scene, _settings(probes="auto", probe_rays=64), tmp_path)
    grids = grid_mod.load(tmp_path / "probes.npz")
    assert len(grids[0]) == len(result.probes[0]) > 0
    np.testing.assert_array_equal(grids[0].coefficients, result.probes[0].coefficients)
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["probes"]["count"] == len(grids[0]) and report["probes"]["invalid"] == 0
    assert report["probes"]["file"].endswith("probes.npz") and report["memory"]["parts_mb"]["light probes"] > 0


def test_a_frame_range_writes_probes_per_frame(tmp_path):
    from detp_bake.run import frames

    def scene_at(frame):  # the lamp rises frame by frame
        lamp = PointLight("Lamp", np.array([0.0, 0.0, 1.0 + frame]), np.array([50.0, 50.0, 50.0]))
        scene = make_scene([("Floor", grid(4, 4, 1), 0.5, True)], [lamp], resolution=8)
        scene.probe_volumes = [_volume("One", (0.0, 0.0, 0.5), (0.1, 0.1, 0.1), (1, 1, 1))]
        return scene
    got = frames.bake_frames(scene_at, frames.parse_frames("1-2"), _settings(probe_rays=64), tmp_path)
    up = [sh9.irradiance(grid_mod.load(tmp_path / f"probes.{f:04d}.npz")[0].coefficients[0], AXES[4])[0]
          for f in (1, 2)]
    assert up[0] > up[1] > 0  # farther from the lamp on frame 2
    report = json.loads((tmp_path / "report.json").read_text())
    assert [s["probes"]["file"].endswith(f"probes.{f:04d}.npz") for s, f in zip(report["per_frame"], (1, 2))] == [True] * 2


def test_photon_segments_crossing_a_sphere_give_a_point_lights_delta():
    # The paper's idea on a sphere (photon_sphere.py): a point light's photons crossing a probe's
    # sphere give c_k = I/r²·Y_k(d) within their noise (10,000 crossings: about 1 %).
    from detp_bake.probes import photon_sphere
    from detp_bake.transport.photons import PhotonTracer
    lamp = PointLight("Lamp", np.array([0.0, 0.0, 3.0]), np.array([100.0, 100.0, 100.0]))
    scene = make_scene([("Plane", grid(4, 4, 1), 0.0, True)], [lamp], resolution=8)
    g = grid_mod.ProbeGrid.full("One", _volume("One", (0.3, 0.0, 1.0), (0.5, 0.5, 0.5), (1, 1, 1)).matrix, (1, 1, 1))
    spheres = photon_sphere.SphereGather([g])
    for batch in PhotonTracer(scene, 1_000_000, 0, seed=1).batches():
        spheres.add(batch)
    d = lamp.position - g.positions[0]
    expected = sh9.project((d / np.linalg.norm(d))[None], (lamp.power / (4 * np.pi) / (d @ d))[None])
    assert 9000 < spheres.crossings[0] < 11000
    np.testing.assert_allclose(spheres.coefficients()[0], expected, atol=0.03 * expected[0, 0])


def test_a_shadowmask_lights_bounce_stays_in_the_probes():
    # Subtract mode: the lightmaps lack the masked lamp's direct light, but a probe above the lit
    # floor must still see the floor lit by it (masked_bounce.py): the probe then holds all the
    # unmasked probe holds but the lamp's own delta.
    lamp = PointLight("Lamp", np.array([0.0, 0.0, 2.0]), np.array([100.0, 100.0, 100.0]))
    scene = make_scene([("Floor", grid(6, 6, 2), 0.5, True)], [lamp], resolution=32)
    probe = np.array([0.5, 0.0, 1.0])
    scene.probe_volumes = [_volume("One", probe, (0.1, 0.1, 0.1), (1, 1, 1))]
    plain = bake.compute(scene, _settings(probe_rays=4096)).probes[0].coefficients[0]
    masked = bake.compute(scene, _settings(probe_rays=4096, shadowmask=("Lamp",))).probes[0].coefficients[0]
    d = lamp.position - probe
    delta = sh9.project((d / np.linalg.norm(d))[None], (lamp.power / (4 * np.pi) / (d @ d))[None])
    down = np.array([0.0, 0.0, -1.0])
    assert sh9.irradiance(masked, down)[0] > 0.5 * sh9.irradiance(plain, down)[0]
    np.testing.assert_allclose(sh9.irradiance(masked, AXES), sh9.irradiance(plain - delta, AXES), rtol=0.03,
                               atol=0.005)


def test_the_job_has_a_probes_phase_that_a_cancel_ends(tmp_path):
    from detp_bake.run import job as job_mod
    lamp = PointLight("Lamp", np.array([0.0, 0.0, 1.0]), np.full(3, 50.0))
    scene = make_scene([("Floor", grid(2.0, 2.0, 2), 0.5, True)], [lamp], resolution=8)
    settings = _settings(probes="auto", probe_spacing=0.5, probe_rays=16)
    events = list(job_mod.Job(scene, settings, tmp_path / "done").events())
    phases = [e.phase for e in events if isinstance(e, job_mod.Phase)]
    assert phases[-2:] == ["probes", "write"] and isinstance(events[-1], job_mod.Result)
    assert (tmp_path / "done" / "probes.npz").is_file()
    job = job_mod.Job(scene, settings, tmp_path / "cancelled")
    hook = job._progress

    def cancel_in_probes(p):
        hook(p)
        if p.phase == "probes":
            job.cancel()
    job._progress = cancel_in_probes
    events = list(job.events())
    assert isinstance(events[-1], job_mod.Cancelled) and events[-1].phase == "probes"
    assert not (tmp_path / "cancelled").exists() or list((tmp_path / "cancelled").iterdir()) == []


def test_an_hdri_sky_is_read_by_direction():
    # An HDRI bright above the horizon (2) and dark below it, turned on its side by its rotation
    # (its zenith along +x): the probe reads E/π = 2 facing +x and 0 facing −x (band 2 is exact
    # there for a sky of two halves), 1 facing up.
    from detp_bake.transport.environment import EnvironmentMap
    image = np.zeros((32, 64, 3), np.float32)
    image[16:] = 2.0  # rows from the nadir: the upper half of the image is the upper sky
    turn = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # image z = world x
    scene = make_scene([("Speck", grid(0.01, 0.01, 1, z=-50.0), 0.0, True)], [], resolution=4)
    scene.world_map = EnvironmentMap(image, turn)
    scene.probe_volumes = [_volume("One", (0.0, 0.0, 0.0), (0.1, 0.1, 0.1), (1, 1, 1))]
    (g,) = bake.compute(scene, _settings(probe_rays=4096)).probes
    reads = sh9.irradiance(g.coefficients[0], AXES)[:, 0]
    np.testing.assert_allclose(reads[[0, 1, 4]], [2.0, 0.0, 1.0], atol=0.03)
