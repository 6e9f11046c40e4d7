"""Density estimators, registered by name.

Every estimator has one shape: built from the texels and the settings, it is fed photon batches as
they are traced (`add`), then `finish` returns the irradiance E (W/m², RGB) at every texel and a
dict of counters for report.json. Streaming estimators do their work in `add`, so memory stays
bounded whatever the photon count; others keep what they need until `finish`.

A bake may also be estimated in runs of batches, here or on a cluster's workers (bake.trace_batches):
`take` hands over what `add` gathered since the last take, summed from zero, and `absorb` adds such
sums (a bake's total, added up in batch order by bake.Totals) back in before `finish`. Float sums
depend on the order they are added in; this way they depend on the batch numbers alone.
"""
from __future__ import annotations

from typing import Callable, Optional

from ..errors import BakeError
from ..lightmap.texels import TexelSet
from .base import (REGISTRY, Context, Estimate, Estimator, EstimatorSettings, FrameState,  # noqa: F401 (re-exported)
                   register)
# They register themselves, in this order (the order of names()).
from . import texel_histogram, disc_index, sphere_cache, hybrid, detp, photon_map  # noqa: F401,E402


def names() -> list[str]:
    """Every estimator, in the order the panel and the help list them."""
    return list(REGISTRY)


def get(name: str) -> type[Estimator]:
    if name not in REGISTRY:
        raise BakeError(f"unknown estimator '{name}' (choose one of: {', '.join(REGISTRY)})")
    return REGISTRY[name]


def read_segments(chosen) -> bool:
    """Whether any estimator of `chosen` reads the photons' path segments: the tracer records them
    only then (for the texel histogram alone, 40 bytes a segment copied for nothing)."""
    return any(get(name).segments for name in chosen)


def compare_order(chosen) -> list[str]:
    """The estimators of `chosen` as Compare lays them out: the baseline first, then as listed."""
    chosen = set(chosen)
    return sorted((n for n in names() if n in chosen), key=lambda n: not REGISTRY[n].baseline)


def compare_defaults() -> list[str]:
    """Compare's default set."""
    return compare_order(n for n in names() if REGISTRY[n].compared)


def create(name: str, texels: TexelSet, settings: EstimatorSettings,
           progress: Optional[Callable[[float], None]] = None, context: Optional[Context] = None) -> Estimator:
    return get(name)(texels, settings, progress, context)
