"""What every estimator is: its settings, its context, its result and the base class, with the
registry they enter by name. Apart from the package's __init__, which imports every estimator, so
that an estimator module imports this one and nothing imports back.

Labels and help come from options.py (ESTIMATORS), where the panel and the command line read them:
declared once, and the registry checks each estimator is declared there.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ..errors import BakeError
from ..options import ESTIMATORS, default
from ..transport.photons import PhotonBatch
from ..lightmap.texels import TexelSet


@dataclass
class EstimatorSettings:
    """The estimators' settings; defaults, ranges and help in options.py."""
    k: int = default("k")  # photon map: neighbours
    normal_agreement: float = 0.8  # photon map: min cos between hit and texel normals
    # DETP family: disc radius in texels of each lightmap (None: options.RADIUS_TEXELS_INDIRECT or
    # RADIUS_TEXELS_ALL, bake.with_disc_radius), or in metres (overrides texels)
    radius_texels: Optional[float] = default("radius_texels")
    radius: Optional[float] = default("radius")
    q: float = default("q")  # sphere cache: ratio of successive sphere radii
    kernel: str = default("kernel")  # DETP family: constant or epanechnikov
    # hybrid: the moving objects' texels by sphere_cache (the paper's choice) or by a disc index of
    # their own, rebuilt every frame (measured faster here: benchmarks/frames.py)
    hybrid_moving: str = default("hybrid_moving")


@dataclass
class Context:
    """What an estimator may need to know of the bake beyond the texels."""
    scene_radius: float = 1.0
    expected_segments: int = 0  # an estimate made before tracing, for work limits
    clearance: Optional[np.ndarray] = None  # per texel, free distance in its tangent plane (DETP discs)
    rise: Optional[np.ndarray] = None  # per texel, its own surface's height in front of its disc (rise.py)
    extent: Optional[np.ndarray] = None  # per texel, the size of its own piece of surface (rise.piece_extent)
    frames: Optional["FrameState"] = None  # set when baking a frame range (frames.py)
    scene: Optional[object] = None  # the (recentred) Scene, for estimators that read its triangles
    directional: bool = False  # also sum L1, each sample's share times its direction (lightmap/sh.py)


@dataclass
class FrameState:
    """What a frame range shares between its frames: which baked objects move over the range, and
    what estimators keep from one frame to the next (by estimator name), such as the hybrid's index
    over the static objects' discs."""
    moving: frozenset = frozenset()
    keep: dict = field(default_factory=dict)
    # Where the moving objects are: a box (lo, hi) per object and frame, (K, 2, 3); None: unknown.
    # With the lights unchanged, direct light is re-sampled only near them (frame_direct.py).
    moving_boxes: Optional[np.ndarray] = None
    lights_change: bool = False


@dataclass
class Estimate:
    irradiance: np.ndarray  # (N, 3) float64, W/m²
    counters: dict = field(default_factory=dict)
    l1: Optional[np.ndarray] = None  # (N, 9) float64, W/m² times unit directions (lightmap/sh.py), when directional


class Estimator:
    """Base class: subclasses set `name` and implement `add` and `finish`. The class attributes
    say what an estimator is and needs, so the pipeline, the memory estimate, the command line and
    the panel ask it instead of naming estimators."""
    name = ""
    label = ""  # the name people read (panel, help): set by register from options.ESTIMATORS
    description = ""
    streaming = False  # True when `add` consumes a batch completely
    discs = False  # DETP family: tangent discs, which need their radii, tangent clearance and a sun margin
    every_texel = False  # estimates every texel at no cost per texel: the bake gives it no sites (sites.py)
    for_denoiser = False  # its noise is white, texel by texel: made to be denoised (the bake warns without)
    stores_hits = False  # keeps every surface hit until `finish` (memory grows with the photons)
    segments = True  # reads the batches' path segments (the tracer copies them only when one does)
    # Reads the texels' positions or normals while tracing (its discs, its preview's gathers); one
    # that does not lets the bake set them aside meanwhile (texels.geometry_set_aside).
    texel_geometry_while_tracing = True
    baseline = False  # Compare puts it first: the others are measured against it
    compared = True  # in Compare's default set
    # Segments an estimator gathers before it works through them: the bake reads its sums (for the
    # noise estimate) no more often than that, so the reading costs no extra work.
    group_segments = 0
    # The live preview's `current` gathers over every hit so far, not just reads sums: worth
    # refreshing less often (job.py).
    slow_preview = False
    bytes_per_texel = 160  # memory an estimator keeps per texel (discs, index, sums): for the estimate
    directional = False  # sums L1 too when Context.directional (under 'l1' in its take sums)

    def __init__(self, texels: TexelSet, settings: EstimatorSettings,
                 progress: Optional[Callable[[float], None]] = None, context: Optional[Context] = None):
        self.texels = texels
        self.settings = settings
        self.progress = progress or (lambda fraction: None)
        self.context = context or Context()

    @classmethod
    def fixed_noise(cls, settings: EstimatorSettings) -> Optional[float]:
        """Relative noise that does not fall with more photons (a noise target cannot be met), or
        None when the noise falls with the photons and is measured from the batches."""
        return None

    def add(self, batch: PhotonBatch) -> None:
        raise NotImplementedError

    def finish(self) -> Estimate:
        raise NotImplementedError

    def take(self) -> dict:
        """What `add` gathered since the last take, and start again from zero: {key: value} where
        values add with += (arrays, numbers, lists). Streaming estimators put their per-texel
        sums, in texel order, under 'irradiance'."""
        raise NotImplementedError

    def absorb(self, sums: dict) -> None:
        """Add sums made by `take` (of this estimator or of one built alike on another machine)."""
        raise NotImplementedError

    def current(self, sums: dict, progress: Optional[Callable[[float], None]] = None) -> np.ndarray:
        """For a live preview: the irradiance (N, 3) of the batches whose `take` sums were added
        into `sums` (the bake's running totals), not yet divided by the share they cover. `sums`
        stays as it is, so the finished bake is the same with or without previews."""
        return sums["irradiance"]


REGISTRY: dict[str, type[Estimator]] = {}


def register(cls: type[Estimator]) -> type[Estimator]:
    """Enter an estimator under its name, with the label and help options.ESTIMATORS gives it."""
    text = {name: (label, help) for name, label, help in ESTIMATORS}
    if cls.name not in text:
        raise BakeError(f"estimator '{cls.name}' is not declared in options.ESTIMATORS")
    cls.label, cls.description = text[cls.name]
    REGISTRY[cls.name] = cls
    return cls
