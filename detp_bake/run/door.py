"""The door of a bake: what can be checked before any long work, checked once.

A front end (the command line, the panel's operators) asks for an Admission before it exports the
scene: every estimator's settings validated, the directional options checked, the output folder
made and proved writable. The job and the pipeline take the admission as it is instead of checking
again; the photon count the bake traces is chosen once the scene is known (`with_photons`), and
every later stage reads that number.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Optional

from ..lightmap import images, texels as texels_mod
from ..options import AUTO_PHOTONS, PHOTONS_PER_TEXEL
from ..transport import scattering
from . import directional
from .settings import BakeSettings


@dataclass(frozen=True)
class Admission:
    """Settings that passed the door, for the estimators `names` (the first is the bake's own), and
    the output folder (None: nothing is written). `automatic`: `settings.photons` was chosen by
    `auto_photons` (the bake says so), not set by the person."""
    settings: BakeSettings
    names: tuple
    out_dir: Optional[Path] = None
    automatic: bool = False


def admit(settings: BakeSettings, names=None, out_dir=None, frame_state=None) -> Admission:
    """Check everything about a bake that needs no scene; BakeError naming the setting or folder."""
    names = (settings.estimator,) if names is None else tuple(dict.fromkeys(names))
    for name in names:
        replace(settings, estimator=name).validate()
    directional.check(settings, names, frame_state)
    out = images.check_writable_dir(out_dir) if out_dir is not None else None
    return Admission(settings, names, out)


def admitted(settings, names=None, out_dir=None, frame_state=None) -> Admission:
    """`settings` as they are when they passed the door already (an Admission), else `admit`ted."""
    return settings if isinstance(settings, Admission) else admit(settings, names, out_dir, frame_state)


def auto_photons(scene, settings: BakeSettings) -> int:
    """The photons a bake traces: the setting, or when it is 0, `photons_per_texel` for every texel
    of the lightmaps to bake (objects without a resolution of their own take the setting's; an atlas
    counts once), within AUTO_PHOTONS: more texels need more photons for the same noise per texel."""
    if settings.photons:
        return int(settings.photons)
    firsts = (scene.objects[members[0]] for _, members in texels_mod.images(scene))
    texels = sum((o.resolution if o.resolution > 0 else settings.resolution) ** 2 for o in firsts)
    low, high = AUTO_PHOTONS
    per_texel = photons_per_texel(scattering.survival(scene.albedo, scene.positions), settings)
    return int(min(max(per_texel * texels, low), high))


def photons_per_texel(survival: float, settings: BakeSettings) -> float:
    """PHOTONS_PER_TEXEL, times `roulette_share`: the noise PHOTONS_PER_TEXEL gave with the roulette
    at the first landing."""
    return PHOTONS_PER_TEXEL * roulette_share(survival, settings)


def roulette_share(survival: float, settings: BakeSettings) -> float:
    """How many photons with the roulette at their first landing one photon of this bake's is worth,
    inverted: the surfaces' `survival` q (scattering.survival) where the photons bring the indirect
    light alone (shadow rays the direct), as their first reflection is certain (scattering.py) and
    q times the photons then give the same noise; else 1. At least 1/64 (a black scene has no
    indirect light to count)."""
    if settings.direct != "sampled":
        return 1.0
    return max(survival, 1.0 / 64.0)


def with_photons(admission: Admission, scene) -> Admission:
    """The admission with its photon count chosen for `scene` (once: a count already there stays)."""
    if admission.settings.photons:
        return admission
    chosen = replace(admission.settings, photons=auto_photons(scene, admission.settings))
    return replace(admission, settings=chosen, automatic=True)
