"""The default photon count follows the texels to bake (bake.auto_photons), and the bake says so."""
import numpy as np

from detp_bake.run import bake as bake_mod
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.scene import PointLight
from synthetic import grid, make_scene


def _plane(resolution):
    light = PointLight("Lamp", np.array([0.0, 0.0, 1.0]), np.full(3, 100.0))
    return make_scene([("Floor", grid(2.0, 2.0, 2), 0.5, True)], [light], resolution=resolution)


def test_the_default_grows_with_the_texels():
    counts = [bake_mod.auto_photons(_plane(res), BakeSettings()) for res in (64, 512, 1024, 4096)]
    assert counts == [1_000_000, 16 * 512 ** 2, 16 * 1024 ** 2, 64_000_000]
    assert bake_mod.auto_photons(_plane(1024), BakeSettings(photons=123_456)) == 123_456  # --photons fixes it


def test_the_bake_says_what_it_chose():
    said = []
    r = compute(_plane(300), BakeSettings(denoise=False), progress=said.append)
    chosen = 16 * 300 ** 2
    assert r.stats.photons == chosen == r.settings.photons == r.report()["settings"]["photons"]
    first = [p.message for p in said if p.phase == "prepare"][0]
    print(first)
    assert first.startswith("Photons: 1.44M, chosen for the lightmaps' texels") and " s on " in first
    quiet = []
    compute(_plane(64), BakeSettings(photons=50_000, denoise=False), progress=quiet.append)
    assert not any(p.message.startswith("Photons:") for p in quiet)
