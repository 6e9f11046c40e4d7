"""One estimator's E/π per texel made into its lightmap images: dilated, or denoised by region with
the fragments smoothed, the direct light apart. The last step of a bake (bake.py), and the one that
holds the most images at once, so what it keeps and lets go is spelled out on one object.

What the denoiser keeps apart (regions) and smooths instead (fragments) is found before tracing
(`plan`), while the texels' positions and normals are at hand: the bake then sets them aside once,
for tracing and the images, and finds them again at its end (texels.geometry_set_aside).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial
from typing import Optional

import numpy as np

from .. import estimators
from ..lightmap import denoise as denoise_mod, dilation, fragments as fragments_mod, texels as texels_mod, validity

# From this many pixels a lightmap's soft direct light (area lights, emissive meshes, the sky) and its
# indirect light are denoised together: one OIDN run instead of two, where OIDN costs more than the
# photons (docs/real_levels.md). At 64² on the project's scenes together was 0.2-0.5 points of RMSE
# worse on the L-room and the Cornell box, 0.2-0.7 better on the window room and the courtyard.
ONE_PASS_FROM = 1024 * 1024


@dataclass
class Denoising:
    """What the denoiser of every lightmap needs from the texels' geometry, found once: `regions`
    {lightmap: texels that see each other (validity.regions), the objects of an atlas apart
    (validity.by_object)}, denoised apart; `fragments` {lightmap: the texels of charts too narrow for
    OIDN and their neighbours on the surface (fragments.find_all), or None}, smoothed instead."""
    regions: dict = field(default_factory=dict)
    fragments: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)


def plan(texels, scene, caster, threads: int, photons: int = 0) -> Denoising:
    """The regions and fragments of every lightmap (Denoising), with the seconds each took; with
    `photons` (the bake's, in photons with the roulette at the first landing: door.roulette_share),
    a lightmap that can expect few a texel has its wider charts among its fragments too
    (fragments.starved_lightmaps)."""
    out = Denoising()
    t0 = time.perf_counter()
    found = {} if texels.cuts is None else validity.all_regions(texels, texels.cuts, caster, scene, threads)
    for lm in texels.lightmaps:
        labels = found.get(lm.name)
        if len(lm.members) > 1:
            labels = validity.by_object(texels, lm, scene, labels)
        if labels is not None:
            out.regions[lm.name] = labels
    t1 = time.perf_counter()
    starved = fragments_mod.starved_lightmaps(texels, scene, photons)
    out.fragments = fragments_mod.find_all(texels, scene, caster, threads, starved)
    out.seconds = {"regions": t1 - t0, "fragments": time.perf_counter() - t1}
    return out


@dataclass
class Images:
    """What `Finishing.images` makes: per lightmap, its image, the texels' mask and the mask of
    texels whose centre lies on the surface; the denoiser's seconds and warnings."""
    images: dict = field(default_factory=dict)
    masks: dict = field(default_factory=dict)
    centre_masks: dict = field(default_factory=dict)
    denoise_seconds: Optional[float] = None
    warnings: list = field(default_factory=list)


@dataclass
class Finishing:
    """How one estimator's lightmaps are made. `direct`: the direct irradiance E inside the value,
    denoised on its own and the rest (the indirect estimate) on its own; this object may hold its
    only reference, and lets it go once the last lightmap has taken its part. `sharp`: the part of
    `direct` from point, spot and sun lights, kept as the shadow rays give it (exact away from
    penumbrae; docs/real_levels.md). `denoising`: the regions denoised apart and the fragments
    smoothed instead (`plan`); it reads no texel position or normal."""
    settings: object  # settings.BakeSettings
    texels: texels_mod.TexelSet
    direct: Optional[np.ndarray] = None
    sharp: Optional[np.ndarray] = None
    denoising: Denoising = field(default_factory=Denoising)

    def images(self, value: np.ndarray, counters: dict) -> Images:
        """The per-texel E/π `value` as dilated (and denoised) images."""
        settings, texels = self.settings, self.texels
        out = Images()
        denoise = settings.denoise and denoise_mod.available()
        if settings.denoise and not denoise:
            out.warnings.append("lightmaps not denoised: the pyoidn package is not installed")
        if not denoise and estimators.get(settings.estimator).for_denoiser:
            out.warnings.append(f"estimator '{settings.estimator}' without denoising: its lightmaps keep the "
                                "photons' noise texel by texel (disc_index gives smoother raw lightmaps)")
        t0 = time.perf_counter()
        for lm in texels.lightmaps:
            pixel = texels.pixel[lm.texels]
            if denoise:
                out.images[lm.name], mask = self._denoised(lm, value, counters)
            else:
                img, mask = texels_mod.to_image(value[lm.texels], lm, pixel)
                out.images[lm.name] = dilation.dilate(img, mask, settings.margin, in_place=True)
            out.masks[lm.name] = mask
            out.centre_masks[lm.name] = centre = np.zeros_like(mask)
            at_centre = texels.centre_inside[lm.texels]
            if texels.cuts is not None:
                at_centre = at_centre & ~texels.cuts.moved[lm.texels]
            centre.flat[pixel[at_centre]] = True
        if denoise:
            out.denoise_seconds = time.perf_counter() - t0
        return out

    def _denoised(self, lm, value, counters) -> tuple:
        """Lightmap `lm` denoised (by region, its fragments smoothed) and its mask."""
        pixel = self.texels.pixel[lm.texels]
        mask = np.zeros(lm.height * lm.width, bool)
        mask[pixel] = True
        mask = mask.reshape(lm.height, lm.width)
        frag = self.denoising.fragments.get(lm.name)
        counters["fragment_texels"] = counters.get("fragment_texels", 0) + (len(frag) if frag else 0)
        return self._parts(lm, value, frag, mask, pixel), mask

    def _parts(self, lm, value, frag, mask, pixel) -> np.ndarray:
        """With `direct`, the indirect part and the soft emitters' direct part are denoised apart
        (together from ONE_PASS_FROM pixels) and the sharp lights' part added as the shadow rays
        gave it. Each part is made per texel and scattered into one image the denoiser may work in,
        and the sharp part's image only once the denoiser is done: at 2048² each image is 50 MB."""
        texels, margin = self.texels, self.settings.margin
        area = lambda: texels_mod.to_image(texels.area[lm.texels, None], lm, pixel)[0][..., 0]  # noqa: E731
        denoised = partial(denoise_mod.denoise_lightmap, mask=mask, margin=margin, weights=area,
                           regions=self.denoising.regions.get(lm.name), fragments=frag,
                           apart=denoise_mod.FILL_RINGS if len(lm.members) > 1 else 1, own=True)
        image = lambda values: texels_mod.to_image(values, lm, pixel)[0]  # noqa: E731
        if self.direct is None:
            return denoised(image(value[lm.texels]))
        # E/π per texel, in float32 as the images hold it: the indirect part (value less the direct
        # light), and the direct light less the sharp lights' part (what the soft emitters gave).
        per_texel = lambda a: (a[lm.texels] / np.float32(np.pi)).astype(np.float32, copy=False)  # noqa: E731
        first = per_texel(self.direct)
        if lm is texels.lightmaps[-1]:
            self.direct = None
        rest = np.subtract(value[lm.texels], first)
        np.maximum(rest, 0.0, out=rest)
        if self.sharp is not None:
            np.subtract(first, per_texel(self.sharp), out=first)
            np.maximum(first, 0.0, out=first)
        parts = [rest, first]  # each part's only reference: scattered, it goes
        rest = first = None
        if self.sharp is not None and lm.width * lm.height >= ONE_PASS_FROM:  # soft direct + indirect: one run
            parts[0] += parts.pop()
            out = denoised(image(parts.pop()))
        else:
            out = denoised(image(parts.pop(0)))
            out += denoised(image(parts.pop()))
        if self.sharp is not None:
            out += dilation.dilate(image(per_texel(self.sharp)), mask, margin, in_place=True)
        return out
