"""A bake's settings (BakeSettings): what one bake needs to know. The settings a person chooses take
their defaults, ranges and help from options.py; a front end builds them with `from_choices`."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .. import estimators, options
from ..errors import BakeError
from ..estimators import EstimatorSettings
from ..lightmap import images
from ..options import MAX_PHOTONS, default


@dataclass
class BakeSettings:
    """Everything one bake needs to know. The settings a person chooses take their defaults, ranges
    and help from options.py; build them from what a front end holds with `from_choices`."""
    # texel_histogram: with shadow rays for direct light and OIDN, the best lightmap per second on
    # every scene measured (README, benchmarks/quality.py); disc_index: the best without a denoiser.
    estimator: str = default("estimator")
    photons: int = default("photons")  # 0: automatic, from the texels to bake (auto_photons)
    # sampled: direct light by shadow rays at every texel, the estimator sees indirect light only;
    # photons: the estimator sees every segment (the paper's experiments).
    direct: str = default("direct")
    direct_samples: int = default("direct_samples")  # shadow rays per texel and light with extent
    bounces: Optional[int] = default("bounces")  # None: the scene's own Cycles diffuse bounces
    seed: int = default("seed")
    resolution: int = default("resolution")  # default per-object lightmap size (objects may override)
    margin: int = default("margin")  # dilation, pixels
    # Light probes (probes/): off, an automatic grid at probe_spacing metres, or the scene's Light
    # Probe Volumes; probe_rays gather rays per probe.
    probes: str = default("probes")
    probe_spacing: float = default("probe_spacing")
    probe_rays: int = default("probe_rays")
    # Atlases (lightmap/atlas.py): the Blender export packs the charts; the bake sees objects that
    # share an image (BakeObject.image).
    lightmaps: str = default("lightmaps")
    texel_density: float = default("texel_density")
    atlas_size: int = default("atlas_size")
    atlas_padding: int = default("atlas_padding")
    atlas_charts: str = default("atlas_charts")
    directional: str = default("directional")  # none, sh or dominant (lightmap/sh.py)
    # Lights whose visibility goes into a shadowmask, and whether their direct light leaves the lightmap
    shadowmask: tuple = default("shadowmask")
    shadowmask_mode: str = default("shadowmask_mode")
    formats: tuple = ("exr",)
    half: bool = False
    threads: int = default("threads")  # 0: all cores
    batch_size: int = 100_000
    memory_budget_mb: int = default("memory_budget_mb")  # 0: 80 % of the free memory (check_memory)
    # Stop tracing early (photons is then the most to trace): once every lightmap's relative noise
    # is at most target_noise per cent, or before time_limit seconds of tracing and estimating.
    target_noise: float = default("target_noise")
    time_limit: float = default("time_limit")
    denoise: bool = default("denoise")  # OIDN on every lightmap (chart-aware; denoise.py), when pyoidn is installed
    keep_raw: bool = False  # also write the lightmaps as they were before denoising (<name>.<estimator>.raw.exr)
    # Texels between the sites where the estimator runs (sites.py), with sampled direct light: 0 is
    # automatic (2 on lightmaps of 256² and more, 1 below); the paper's mode and frame ranges always
    # estimate every texel. The texels between sites blend their neighbouring sites.
    indirect_spacing: int = default("indirect_spacing")
    estimator_settings: EstimatorSettings = field(default_factory=EstimatorSettings)

    @classmethod
    def from_choices(cls, choices: dict, **rest) -> "BakeSettings":
        """Settings from what a front end holds: `choices` maps option names (options.py) to the
        values the person chose, automatic ones as their `auto` value; `rest` sets other fields
        (formats, half, keep_raw). Options left out keep their defaults. With automatic photons and
        a noise target or a time limit, the photons are the most there may be."""
        core = {name: options.BY_NAME[name].core(value) for name, value in choices.items()}
        unknown = sorted(set(core) - set(options.BY_NAME))
        if unknown:
            raise BakeError(f"unknown setting(s): {', '.join(unknown)}")
        es = {n: v for n, v in core.items() if options.BY_NAME[n].estimator}
        bs = {n: v for n, v in core.items() if not options.BY_NAME[n].estimator}
        if bs.get("photons", cls.photons) == 0 and (bs.get("target_noise") or bs.get("time_limit")):
            bs["photons"] = MAX_PHOTONS
        return cls(**bs, **rest, estimator_settings=EstimatorSettings(**es))

    def validate(self) -> None:
        """Raise BakeError naming the first setting that cannot work."""
        def bad(setting, value, why):
            raise BakeError(f"setting '{setting}' = {value!r}: {why}")
        for opt in options.OPTIONS:
            value = getattr(self.estimator_settings if opt.estimator else self, opt.name)
            if isinstance(value, np.integer):
                value = int(value)
            why = opt.check(value)
            if why:
                bad(opt.name, value, why)
        unknown = [f for f in self.formats if f not in images.WRITERS]
        if unknown or not self.formats:
            bad("formats", self.formats, f"choose from {', '.join(images.WRITERS)}")
        if self.indirect_spacing > 1 and self.direct != "sampled":
            bad("indirect_spacing", self.indirect_spacing, "needs direct='sampled': with direct='photons' the estimator "
                "sees direct light too, whose shadow edges blending between sites would blur")
        if self.batch_size < 1:
            bad("batch_size", self.batch_size, "must be positive")
        fixed = estimators.get(self.estimator).fixed_noise(self.estimator_settings)
        if self.target_noise and fixed is not None:
            bad("target_noise", self.target_noise, f"the {self.estimator} estimator's noise does not fall with "
                f"more photons (about {100 * fixed:.2g} % whatever the count): use a DETP estimator")
