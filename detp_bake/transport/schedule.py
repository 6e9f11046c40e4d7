"""Which light emits each photon, batch by batch: every batch is a small bake of its own.

Each batch shares its photons out between the emitters in proportion to their flux (largest
remainder, `lights.allocate`), and every photon carries its emitter's flux times the batch's share of
the bake, over that emitter's count in the batch. So each batch is an unbiased estimate of its share
of the lightmaps, and any prefix of the batches is an unbiased estimate of the whole once divided by
the share it covers (`share(k)`). That is what lets a bake stop early, at a noise target or a time
limit, and what makes the spread between batches a noise estimate (bake.py).

Photon ids run on across batches; a photon's origin, direction and flux depend on the seed and its
id alone, so the records do not depend on the thread count or on how batches are cut into streams.
"""
from __future__ import annotations

import numpy as np

from .. import sampling
from .lights import Emitter, allocate


class BatchSchedule:
    """`photons` photons in batches of `batch_size` (the last one shorter)."""

    def __init__(self, emitters: list[Emitter], photons: int, seed: int, batch_size: int):
        self.emitters = emitters
        self.photons = int(photons)
        self.batch_size = int(batch_size)
        self.key = sampling.seed_key(seed)
        self.count = -(-self.photons // self.batch_size)
        last = self.photons - (self.count - 1) * self.batch_size
        # Every full batch shares out alike; only the last may differ.
        self._full = allocate(emitters, self.batch_size)
        self._last = allocate(emitters, last)
        self._sizes = (self.batch_size, last)

    def _plan(self, index: int) -> tuple[np.ndarray, int]:
        """(photons per emitter, photons asked for) of batch `index`."""
        if index == self.count - 1:
            return self._last, self._sizes[1]
        return self._full, self._sizes[0]

    def ids(self, index: int) -> tuple[int, int]:
        """The photon ids of batch `index`: [start, stop)."""
        start = index * int(self._full.sum())
        return start, start + int(self._plan(index)[0].sum())

    @property
    def total(self) -> int:
        """Photons over all batches (at least `photons`: every emitter gets one per batch)."""
        return self.ids(self.count - 1)[1]

    def weight(self, index: int) -> float:
        """Batch `index`'s share of the bake."""
        return self._plan(index)[1] / self.photons

    def share(self, batches: int) -> float:
        """The share of the bake the first `batches` batches cover."""
        if batches >= self.count:
            return 1.0
        return batches * self.batch_size / self.photons

    @property
    def emitted_flux(self) -> np.ndarray:
        return np.sum([e.flux for e in self.emitters], axis=0)

    def emit(self, index: int, start: int, stop: int, origins: np.ndarray, dirs: np.ndarray,
             flux: np.ndarray, rng: np.ndarray) -> None:
        """Photons [start, stop) of batch `index` into rows 0 … stop − start of the (N, 3) arrays,
        their random states into `rng` (uint64; empty: not kept)."""
        counts, _ = self._plan(index)
        first, _ = self.ids(index)
        weight = self.weight(index)
        a = first
        for e, n in zip(self.emitters, counts):
            lo, hi = max(a, start), min(a + int(n), stop)
            if hi > lo:
                rows = slice(lo - start, hi - start)
                # A photon carries flux / (n / weight): the n photons carry `weight` of the flux.
                e.emit(self.key, lo, hi - lo, n / weight, origins[rows], dirs[rows], flux[rows],
                       rng[rows] if len(rng) else rng)
            a += int(n)
