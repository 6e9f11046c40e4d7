"""Direct light by shadow rays (`--direct sampled`) against closed-form irradiance (docs/design.md, Ground truths),
and against the photons' own estimate of the same light."""
import numpy as np
import pytest

from detp_bake.run.bake import BakeSettings, compute
from detp_bake.transport.direct import direct_irradiance
from detp_bake.estimators import EstimatorSettings
from detp_bake.rays import RayCaster
from detp_bake.scene import AreaLight, PointLight, SpotLight, SunLight
from detp_bake.lightmap.texel_area import SPAN, spread_reach
from detp_bake.lightmap.texels import rasterise
from synthetic import grid, make_scene, uv_sphere


def _direct(scene, samples=16, seed=0, threads=1, spread=False):
    """Direct light at the texel centres (closed forms hold there), or over their squares (`spread`)."""
    texels = rasterise(scene)
    e, info = direct_irradiance(scene, texels, RayCaster(scene.positions), samples, seed, threads, spread=spread)
    return texels, e, info


def test_point_light_over_a_plane_is_exact():
    """E(ρ) = I·h/(h²+ρ²)^{3/2}, I = P/(4π): one shadow ray per texel, no noise at all."""
    h, power = 1.0, 100.0
    sc = make_scene([("Plane", grid(4.0, 4.0, 8), 0.5, True)],
                    [PointLight("Lamp", np.array([0.0, 0.0, h]), np.full(3, power))], resolution=32)
    texels, e, info = _direct(sc)
    x = texels.position
    rho2 = x[:, 0] ** 2 + x[:, 1] ** 2
    expected = power / (4 * np.pi) * h / (h * h + rho2) ** 1.5
    assert np.abs(e[:, 0] / expected - 1).max() < 0.01
    assert info["rays"] == len(texels)  # exactly one ray each


def test_sun_on_a_plane_and_its_shadow():
    """A tilted sun of strength S gives S·cosθ on an open plate (within 0.5 %), and nothing under
    an opaque square held above it, with a sharp shadow edge where the geometry puts it."""
    s, tilt = 3.0, np.radians(30)
    sun = SunLight("Sun", np.array([0.0, np.sin(tilt), -np.cos(tilt)]), np.full(3, s))
    blocker = grid(0.6, 0.6, 1, z=0.5)
    sc = make_scene([("Plate", grid(4.0, 4.0, 4), 0.5, True), ("Blocker", blocker, 0.5, False)],
                    [sun], resolution=64)
    texels, e, _ = _direct(sc)
    x = texels.position[:, :2]
    # Light travels towards +y as it falls: the shadow is the square shifted by 0.5·tan(tilt) to +y.
    shift = 0.5 * np.tan(tilt)
    inside = (np.abs(x[:, 0]) < 0.25) & (np.abs(x[:, 1] - shift) < 0.25)
    outside = (np.abs(x[:, 0]) > 0.4) | (np.abs(x[:, 1] - shift) > 0.4)
    assert np.allclose(e[outside, 0], s * np.cos(tilt), rtol=0.005)
    assert np.all(e[inside] == 0.0)


def test_coaxial_disc_light():
    """A Lambertian disc of radius R and power P at height h, facing down: on its axis
    E = π·L·R²/(R²+h²) with L = P/(π·πR²). 64 stratified samples: within 1 %."""
    radius, h, power = 0.5, 1.0, 80.0
    m = np.eye(4)
    m[2, 3] = h  # local −Z is world −Z: it faces the plane
    light = AreaLight("Disc", m, "DISK", 2 * radius, 2 * radius, np.full(3, power))
    sc = make_scene([("Plane", grid(0.2, 0.2, 2), 0.5, True)], [light], resolution=8)
    texels, e, _ = _direct(sc, samples=64)
    radiance = power / (np.pi * np.pi * radius ** 2)
    # Texels sit within 0.1 m of the axis; E varies by < 0.5 % over that, so take each one's exact value.
    rho2 = np.sum(texels.position[:, :2] ** 2, axis=1)
    exact = [_disc_irradiance(radiance, radius, h, np.sqrt(r2)) for r2 in rho2]
    assert np.allclose(e[:, 0], exact, rtol=0.01)
    assert abs(e[:, 0].mean() / np.mean(exact) - 1) < 0.003
    on_axis = np.pi * radiance * radius ** 2 / (radius ** 2 + h ** 2)
    assert abs(_disc_irradiance(radiance, radius, h, 0.0) / on_axis - 1) < 1e-3  # the quadrature itself


def _disc_irradiance(radiance, radius, h, rho, n=400):
    """E at distance ρ off the axis of a facing Lambertian disc, by midpoint quadrature."""
    r = (np.arange(n) + 0.5) / n * radius
    phi = (np.arange(n) + 0.5) / n * 2 * np.pi
    rr, pp = np.meshgrid(r, phi)
    dx, dy = rr * np.cos(pp) - rho, rr * np.sin(pp)
    d2 = dx * dx + dy * dy + h * h
    integrand = radiance * h * h / d2 ** 2 * rr
    return float(integrand.sum() * (radius / n) * (2 * np.pi / n))


def test_constant_world_on_an_open_plane():
    """A sky of radiance L over an open plane: E = π·L (within 1 %)."""
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)], [], world=(0.2, 0.4, 0.6), resolution=16)
    texels, e, _ = _direct(sc, samples=64)
    assert np.allclose(e.mean(axis=0), np.pi * np.array([0.2, 0.4, 0.6]), rtol=0.01)
    assert np.allclose(e, np.pi * np.array([0.2, 0.4, 0.6]), rtol=1e-6)  # nothing blocks: every ray counts


@pytest.mark.parametrize("world_map", [False, True])
def test_sky_photons_start_on_the_geometry_and_light_it_as_the_world_does(world_map):
    """Sky photons start on the box of the geometry seen along their direction: on an open plane
    over half of them land (31 % did from a disc of the bounding sphere), and E/π = L."""
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)], [], world=(0.2, 0.4, 0.6), resolution=16)
    if world_map:
        sc.world = np.zeros(3)
        sc.world_map = _env(np.broadcast_to(np.array([0.2, 0.4, 0.6], np.float32), (32, 64, 3)))
    r = compute(sc, BakeSettings(photons=400_000, bounces=0, direct="photons", denoise=False,
                                 estimator_settings=EstimatorSettings(radius=0.2)))
    assert r.stats.hits / r.stats.photons > 0.45
    assert np.allclose(r.value.mean(axis=0), [0.2, 0.4, 0.6], rtol=0.015)


def test_spot_cone_and_point_sphere_limits():
    """A spot's cone cuts the light at the angle Blender's spot size says; a point light with a
    radius is a sphere of the same power, which from afar is the point light."""
    spot = SpotLight("Spot", np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0]), np.full(3, 100.0),
                     np.radians(60), 0.0)
    sc = make_scene([("Plane", grid(4.0, 4.0, 4), 0.5, True)], [spot], resolution=32)
    texels, e, _ = _direct(sc)
    rho = np.linalg.norm(texels.position[:, :2], axis=1)
    edge = np.tan(np.radians(30))
    assert np.all(e[rho > edge + 0.05] == 0.0)
    assert np.allclose(e[rho < edge - 0.05, 0], 100 / (4 * np.pi) / (1 + rho[rho < edge - 0.05] ** 2) ** 1.5,
                       rtol=1e-3)
    far = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)],
                     [PointLight("Ball", np.array([0.0, 0.0, 5.0]), np.full(3, 100.0), radius=0.3)], resolution=8)
    _, e_sphere, _ = _direct(far, samples=64)
    far.lights[0].radius = 0.0
    _, e_point, _ = _direct(far)
    assert np.allclose(e_sphere, e_point, rtol=0.01)


def test_emissive_triangles_match_the_photons():
    """A two-sided emissive square above a floor: the shadow-ray estimate and the photons'
    (DETP, direct only) agree in the mean within 1 %."""
    floor = grid(2.0, 2.0, 2)
    lamp = grid(0.5, 0.5, 1, z=0.8, flip=True)
    sc = make_scene([("Floor", floor, 0.5, True), ("Lamp", lamp, 0.0, False)], [], resolution=32)
    sc.emission[sc.object_named("Lamp").triangles] = 3.0
    sampled = compute(sc, BakeSettings(photons=2000, bounces=0, direct_samples=32))
    photons = compute(sc, BakeSettings(photons=2_000_000, bounces=0, direct="photons",
                                       estimator_settings=EstimatorSettings(radius=0.1)))
    assert abs(sampled.value.mean() / photons.value.mean() - 1) < 0.01


def test_sampled_and_photon_direct_agree_in_a_closed_sphere():
    """Point source Φ in a closed sphere of albedo ρ, 4 bounces: the mean E is Φ/(4πR²)·Σ_{k≤4} ρ^k
    whether direct light is sampled or carried by photons (within 1 %)."""
    radius, rho, power, bounces = 1.0, 0.5, 100.0, 4
    sc = make_scene([("Sphere", uv_sphere(radius, 24, 48, inward=True), rho, True)],
                    [PointLight("Lamp", np.zeros(3), np.full(3, power))], resolution=48)
    expected = power / (4 * np.pi * radius ** 2) * sum(rho ** k for k in range(bounces + 1))
    for direct in ("sampled", "photons"):
        r = compute(sc, BakeSettings(photons=1_000_000, bounces=bounces, direct=direct,
                                     estimator_settings=EstimatorSettings(radius=0.15)))
        mean = np.sum(r.value[:, 0] * np.pi * r.texels.area) / np.sum(r.texels.area)
        assert abs(mean / expected - 1) < 0.01, direct


def test_direct_light_is_the_same_on_any_thread_count():
    area = AreaLight("Panel", np.eye(4) + np.diag([0, 0, 0, 0]), "RECTANGLE", 0.5, 0.3, np.full(3, 40.0))
    area.matrix[2, 3] = 1.0
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True), ("Block", grid(0.4, 0.4, 1, z=0.4), 0.5, False)],
                    [area], world=(0.1, 0.1, 0.1), resolution=96)
    _, one, _ = _direct(sc, seed=3, threads=1)
    _, two, _ = _direct(sc, seed=3, threads=2)
    _, other, _ = _direct(sc, seed=4, threads=2)
    assert np.array_equal(one, two)
    assert not np.array_equal(one, other)


@pytest.mark.parametrize("setting, value", [("direct", "rays"), ("direct_samples", 0), ("direct_samples", 10 ** 6)])
def test_bad_direct_settings_are_refused(setting, value):
    from detp_bake.errors import BakeError
    with pytest.raises(BakeError, match=setting):
        BakeSettings(**{setting: value}).validate()


def _env(image, rotation=np.eye(3)):
    from detp_bake.transport.environment import EnvironmentMap
    return EnvironmentMap(np.asarray(image, np.float32), np.asarray(rotation, float))


@pytest.mark.parametrize("direct", ["sampled", "photons"])
def test_constant_environment_map_is_the_constant_world(direct):
    """An HDRI of one colour lights an open plane as that world colour does: E = π·L."""
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)], [], resolution=16)
    sc.world_map = _env(np.broadcast_to(np.array([0.2, 0.4, 0.6], np.float32), (32, 64, 3)))
    r = compute(sc, BakeSettings(photons=1_000_000, bounces=0, direct=direct, direct_samples=64, denoise=False,
                                 estimator_settings=EstimatorSettings(radius=0.2)))
    assert np.allclose(r.value.mean(axis=0), [0.2, 0.4, 0.6], rtol=0.015)  # E/π = L


@pytest.mark.parametrize("direct", ["sampled", "photons"])
def test_a_bright_spot_in_the_map_lights_like_a_sun_from_where_cycles_puts_it(direct):
    """One bright pixel block at image u = 0.25, v = 0.75 (+y, 45° up, by Cycles' equirectangular
    mapping) over a dark sky: a plane facing +z gets E = L·Ω·cos 45°, and a Mapping rotation
    moves where the spot is in the world."""
    h, w = 64, 128
    img = np.zeros((h, w, 3), np.float32)
    rows, cols = slice(int(0.75 * h) - 1, int(0.75 * h) + 1), slice(int(0.25 * w) - 1, int(0.25 * w) + 1)
    img[rows, cols] = 500.0
    theta = (np.arange(h)[::-1] + 0.5) / h * np.pi
    omega = (2 * np.pi / w) * (np.pi / h) * np.sin(theta)
    e_spot = 500.0 * omega[rows].sum() * 2 * np.cos(np.radians(45))  # two columns
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)], [], resolution=8)
    sc.world_map = _env(img)
    r = compute(sc, BakeSettings(photons=400_000, bounces=0, direct=direct, direct_samples=16, denoise=False,
                                 estimator_settings=EstimatorSettings(radius=0.3)))
    assert np.isclose(r.value[:, 0].mean() * np.pi, e_spot, rtol=0.03)
    # Which way it comes from: a wall facing the spot's world direction sees it, the wall's back
    # does not; with the Mapping rotation (90° about z) the spot moves from +y to R⁻¹·(+y) = +x.
    from detp_bake.transport.direct import direct_irradiance
    from detp_bake.rays import RayCaster
    from detp_bake.lightmap.texels import rasterise
    uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1.0]]])
    turn = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    for rotation, towards in ((np.eye(3), [0, 1.0, 0]), (turn, [1.0, 0, 0])):
        assert np.allclose(rotation.T @ [0, 1.0, 0], towards)
        for facing, lit in ((np.array(towards), True), (-np.array(towards), False)):
            ws = make_scene([("Wall", (_face(facing), np.broadcast_to(facing, (2, 3, 3)).copy(), uv), 0.5, True)],
                            [], resolution=4)
            ws.world_map = _env(img, rotation)
            e, _ = direct_irradiance(ws, rasterise(ws), RayCaster(ws.positions), 16)
            if lit:
                assert e[:, 0].mean() > 0.5 * e_spot
            else:
                assert e[:, 0].mean() < 0.01 * e_spot


def _face(n):
    """Two triangles of a 1 m square through the origin facing n (horizontal n)."""
    t = np.array([-n[1], n[0], 0.0])
    z = np.array([0.0, 0.0, 1.0])
    a, b, c, d = -0.5 * t - 0.5 * z, 0.5 * t - 0.5 * z, 0.5 * t + 0.5 * z, -0.5 * t + 0.5 * z
    tris = np.array([[a, b, c], [a, c, d]])
    if np.dot(np.cross(b - a, c - a), n) < 0:
        tris = tris[:, [0, 2, 1]]
    return tris


def _lit_fraction(sc, texels, lit, n=48):
    """Per texel, the share of the square SPAN wide round its centre that lies on its own triangle
    and is lit (`lit(x, y)`), by an n × n grid of points: what Cycles' jittered samples average to."""
    out = np.empty(len(texels))
    lm = texels.lightmaps[0]
    grid_ = SPAN * ((np.arange(n) + 0.5) / n - 0.5)
    fx, fy = [a.ravel() for a in np.meshgrid(grid_, grid_)]
    for k in range(len(texels)):
        t = texels.triangle[k]
        uv = sc.uvs[t] * [lm.width, lm.height]
        cx, cy = texels.pixel[k] % lm.width + 0.5, texels.pixel[k] // lm.width + 0.5
        m = np.array([[uv[0, 0] - uv[2, 0], uv[1, 0] - uv[2, 0]], [uv[0, 1] - uv[2, 1], uv[1, 1] - uv[2, 1]]])
        l01 = np.linalg.solve(m, np.stack([cx + fx - uv[2, 0], cy + fy - uv[2, 1]]))
        bary = np.vstack([l01, 1.0 - l01.sum(axis=0)])
        on = np.all(bary >= 0.0, axis=0)
        world = bary[:, on].T @ sc.positions[t][[0, 1, 2]]
        out[k] = lit(world[:, 0], world[:, 1]).mean() if on.any() else np.nan
    return out


def test_a_shadow_edge_across_texels_gives_each_its_lit_share():
    """A sun straight down and a plate whose edge crosses the floor's texels at 20°: each texel
    reads S times the share of its middle (the square SPAN wide round its centre, on its
    triangle, where Cycles samples it) in the light,
    not 0 or S by where its centre falls. 16 rays per texel: within 0.1 of the share (RMS) at the
    edge, and the floor's mean within 0.5 % of the lit area."""
    s, phi = 2.0, np.radians(20.0)
    sun = SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, s))  # sharp: --direct-samples rays all the same
    # The blocker: a 4 m square rotated by phi, its edge through (0.03, 0) on the line x·cos + y·sin = 0.03.
    cos, sin = np.cos(phi), np.sin(phi)
    corners = np.array([[0.03, -2.0], [2.03, -2.0], [2.03, 2.0], [0.03, 2.0]]) @ np.array([[cos, sin], [-sin, cos]])
    blocker = np.array([[[*corners[a], 0.5] for a in tri] for tri in ((0, 1, 2), (0, 2, 3))])
    blocker = (blocker, np.broadcast_to([0.0, 0.0, 1.0], blocker.shape).copy(), np.zeros((2, 3, 2)))
    sc = make_scene([("Floor", grid(1.0, 1.0, 8), 0.5, True), ("Blocker", blocker, 0.5, False)], [sun], resolution=32)
    texels, e, _ = _direct(sc, spread=True)
    share = _lit_fraction(sc, texels, lambda x, y: x * cos + y * sin < 0.03)
    edge = (share > 0.0) & (share < 1.0)
    assert edge.sum() > 10
    err = e[:, 0] / s - share
    print(f"edge texels {edge.sum()}: RMS {np.sqrt(np.mean(err[edge] ** 2)):.3f}, far {np.abs(err[~edge]).max():.4f}")
    assert np.sqrt(np.mean(err[edge] ** 2)) < 0.1
    assert np.abs(err[~edge]).max() < 1e-3
    assert abs(e[:, 0].mean() / (s * share.mean()) - 1.0) < 0.005


def test_shadow_edges_of_a_sharp_light_converge_with_more_rays():
    """A sharp sun adds rays only where a texel's first ones disagree. Those first four start at
    the corners of the texel's square (texel_area.square_corner), so a straight edge crossing the
    square is always seen: with 64 rays the edge texels read their lit share to 0.05 RMS, and
    more rays bring them closer. From four points inside the square (before) half the edge
    texels took no more rays: 0.10-0.13 RMS at 16, 64 or 256 rays alike (the error floored)."""
    s, phi, off = 2.0, np.radians(33.0), -0.02
    sun = SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, s))
    cos, sin = np.cos(phi), np.sin(phi)
    corners = np.array([[off, -2.0], [off + 2.0, -2.0], [off + 2.0, 2.0], [off, 2.0]]) @ np.array([[cos, sin],
                                                                                              [-sin, cos]])
    blocker = np.array([[[*corners[a], 0.5] for a in tri] for tri in ((0, 1, 2), (0, 2, 3))])
    blocker = (blocker, np.broadcast_to([0.0, 0.0, 1.0], blocker.shape).copy(), np.zeros((2, 3, 2)))
    sc = make_scene([("Floor", grid(1.0, 1.0, 8), 0.5, True), ("Blocker", blocker, 0.5, False)], [sun], resolution=64)
    rms = {}
    for samples in (16, 64):
        texels, e, _ = _direct(sc, samples=samples, spread=True)
        share = _lit_fraction(sc, texels, lambda x, y: x * cos + y * sin < off)
        edge = (share > 0.0) & (share < 1.0)
        rms[samples] = float(np.sqrt(np.mean((e[edge, 0] / s - share[edge]) ** 2)))
    print(rms)
    assert edge.sum() > 40
    assert rms[64] < 0.05 and rms[64] < 0.6 * rms[16]


def test_rays_start_within_the_reach_frame_ranges_allow_for():
    """frame_direct widens its 'near a moving object' test by texel_area.spread_reach: SPAN/2 of
    one pixel step along u plus one along v, in metres, and half a step more at a chart's border,
    where a texel's centre lies off the plate."""
    sc = make_scene([("Plate", grid(2.0, 1.0, 2, ), 0.5, True)], [], resolution=8)
    sc.uvs[:] = 0.1 + 0.8 * sc.uvs  # the plate's edges 0.3 pixel inside the outer texels' centres
    texels = rasterise(sc)
    reach = spread_reach(texels, sc)
    step = (2.0 + 1.0) / 6.4  # the UVs span 6.4 pixels
    assert texels.centre_inside.any() and not texels.centre_inside.all()
    assert np.allclose(reach[texels.centre_inside], 0.5 * SPAN * step)
    assert np.allclose(reach[~texels.centre_inside], (0.5 + 0.5 * SPAN) * step)


def _lamps(n, radius=0.0, seed=3):
    """`n` point lights of different powers 0.5-1.5 m over the middle of a plane."""
    rng = np.random.default_rng(seed)
    at = np.column_stack([rng.uniform(-1.5, 1.5, n), rng.uniform(-1.5, 1.5, n), rng.uniform(0.5, 1.5, n)])
    powers = rng.uniform(5.0, 50.0, n)
    return [PointLight(f"Lamp{i}", at[i], np.full(3, powers[i]), radius) for i in range(n)]


def test_many_point_lights_over_a_plane_sum_their_closed_forms():
    """40 point lights (more than MANY_LIGHTS: sampled per texel by their weight, many_lights.py):
    at the texel centres E = Σ I·h/(h²+ρ²)^{3/2} within 0.1 % (with nothing in the way the draw by
    weight is exact); over the texels' squares, as the bake casts them, within 1 % on average of
    every light's own rays (within 0.1 % over the plane), on a sixth of their rays."""
    lamps = _lamps(40)
    sc = make_scene([("Plane", grid(4.0, 4.0, 8), 0.5, True)], lamps, resolution=32)
    texels, e, info = _direct(sc)
    assert info["sampled_per_texel"] == 40
    x = texels.position
    expected = sum(l.power[0] / (4 * np.pi) * l.position[2] /
                   (l.position[2] ** 2 + (x[:, 0] - l.position[0]) ** 2 + (x[:, 1] - l.position[1]) ** 2) ** 1.5
                   for l in lamps)
    assert np.abs(e[:, 0] / expected - 1).max() < 1e-3
    _, spread, info = _direct(sc, spread=True)
    own, every = direct_irradiance(sc, texels, RayCaster(sc.positions), 16, 0, 1, spread=True, many_from=10 ** 6)
    assert np.abs(spread[:, 0] / own[:, 0] - 1).mean() < 0.01
    assert abs(spread[:, 0].sum() / own[:, 0].sum() - 1) < 0.001
    assert info["rays"] < every["rays"] / 6


def test_many_lights_are_unbiased_in_the_mean_where_shadows_fall():
    """Sphere lights over a plane with a square held above it: the per-texel draw among the lights
    (with rays of their own for the few that give a texel most of its light) averages, over seeds,
    to what every light's own rays give (64 rays each); each seed alone is noisy under the square's
    shadows."""
    lamps = _lamps(30, radius=0.2, seed=5)
    sc = make_scene([("Plane", grid(4.0, 4.0, 8), 0.5, True), ("Blocker", grid(1.2, 1.2, 1, z=0.3), 0.5, False)],
                    lamps, resolution=24)
    texels = rasterise(sc)
    caster = RayCaster(sc.positions)
    ref, info = direct_irradiance(sc, texels, caster, 64, 0, 1, spread=False, many_from=10 ** 6)
    assert "sampled_per_texel" not in info
    runs = [direct_irradiance(sc, texels, caster, 16, seed, 1, spread=False)[0][:, 0] for seed in range(8)]
    rms = lambda a: np.sqrt(np.mean((a - ref[:, 0]) ** 2)) / np.sqrt(np.mean(ref[:, 0] ** 2))  # noqa: E731
    one = np.mean([rms(run) for run in runs])
    assert one > 0.01  # each seed is noisy under the shadows (7 %; every light's own rays: 0.35 %)
    assert rms(np.mean(runs, axis=0)) < 0.5 * one  # the noise averages out (1/√8 = 0.35): no bias left
    assert abs(np.mean(runs, axis=0).sum() / ref[:, 0].sum() - 1) < 0.002
