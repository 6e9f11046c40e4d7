"""What every source of photons hands the tracer: its name, the flux it emits and a compiled
function that writes its photons (lights.py makes them for lights, meshes and a plain sky;
environment.py for an HDRI world)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

# emit(key, first_id, count, total_count, origins, directions, flux, rng): writes `count` photons,
# ids first_id, first_id + 1, …, into rows 0 … count − 1 of the (N, 3) float32 or float64 arrays,
# and each photon's random state after emission into `rng` (uint64; an empty array: not kept).
# A photon carries 1/total_count of its emitter's flux.
Emit = Callable[[np.uint64, int, int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray], None]


@dataclass
class Emitter:
    name: str
    flux: np.ndarray  # RGB watts actually emitted
    emit: Emit

    @property
    def weight(self) -> float:
        return float(np.mean(self.flux))

    def sample(self, n: int, total: int, rng: np.random.Generator):
        """n photons (float64 origins, directions, flux) keyed by a draw from `rng`."""
        out = [np.empty((n, 3)) for _ in range(3)]
        self.emit(np.uint64(rng.integers(2 ** 64, dtype=np.uint64)), 0, int(n), int(total), *out,
                  np.empty(0, np.uint64))
        return tuple(out)
