"""The probes of one bake as one record: where each probe is, whether it can be trusted, and what it
holds; and the plain file engines and scripts read (`<folder>/probes.npz`).

A grid is a box with a resolution: Blender's Light Probe Volume object is the unit cube [−1, 1]³
under its world matrix, its x/y/z resolution cut that cube into cells, and a probe sits at each
cell's centre (local coordinate −1 + (2i + 1)/r along an axis of r cells). An automatic grid is the
same with an axis-aligned box, and keeps only the probes near geometry: `index` says which cells
hold a probe, so a sparse grid and a full one share one layout. A loader that wants 3D textures
allocates resolution[0]·[1]·[2] cells and writes each probe at its index (x fastest).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import sh9

FILE_NAME = "probes.npz"
FORMAT = "detp_bake.probes/1"


@dataclass
class ProbeGrid:
    """One grid's probes. `coefficients` are sh9's (radiance SH L2, the lightmaps' unit), direct and
    indirect light together, or without the shadowmask lights' direct light when the bake keeps
    those apart; `occlusion` then says, per shadowmask light, how much of it reaches the probe
    (0 to 1), as a lightmap's shadowmask does for a texel."""
    name: str
    matrix: np.ndarray                 # (4, 4) float64: the unit cube [−1, 1]³ to world space
    resolution: tuple[int, int, int]
    index: np.ndarray                  # (N, 3) int32: each probe's cell
    valid: np.ndarray = None           # (N,) bool: rays from it saw mostly front faces
    offset: np.ndarray = None          # (N, 3) float32: virtual offset, world space (0: none)
    coefficients: np.ndarray = None    # (N, 9, 3) float32
    occlusion: np.ndarray = None       # (N, L) float32, L shadowmask lights (L may be 0)
    shadowmask_lights: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self):
        n = len(self.index)
        self.index = np.ascontiguousarray(self.index, dtype=np.int32).reshape(n, 3)
        self.matrix = np.asarray(self.matrix, dtype=np.float64).reshape(4, 4)
        self.resolution = tuple(int(r) for r in self.resolution)
        if self.valid is None:
            self.valid = np.ones(n, dtype=bool)
        if self.offset is None:
            self.offset = np.zeros((n, 3), dtype=np.float32)
        if self.coefficients is None:
            self.coefficients = np.zeros((n, sh9.COEFFICIENTS, 3), dtype=np.float32)
        if self.occlusion is None:
            self.occlusion = np.ones((n, len(self.shadowmask_lights)), dtype=np.float32)

    @classmethod
    def full(cls, name: str, matrix: np.ndarray, resolution) -> "ProbeGrid":
        """Every cell of the box holds a probe (a Light Probe Volume)."""
        r = tuple(int(v) for v in resolution)
        z, y, x = np.meshgrid(*(np.arange(v) for v in r[::-1]), indexing="ij")
        return cls(name, matrix, r, np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1))

    def __len__(self) -> int:
        return len(self.index)

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) float64 world positions of the cells' centres (before any virtual offset)."""
        local = -1.0 + (2.0 * self.index + 1.0) / np.asarray(self.resolution, dtype=np.float64)
        return local @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    @property
    def linear_index(self) -> np.ndarray:
        """(N,) each probe's cell in a dense x-fastest array of the grid's resolution."""
        rx, ry, _ = self.resolution
        return self.index[:, 0] + rx * (self.index[:, 1] + ry * self.index[:, 2])


def save(grids: list[ProbeGrid], path: Path) -> None:
    """Every grid of a bake into one .npz: `grids` (names), then per grid i the arrays
    `<i>.matrix`, `<i>.resolution`, `<i>.index`, `<i>.valid`, `<i>.offset`, `<i>.coefficients`
    (N, 9, 3), `<i>.occlusion` (N, L) and `<i>.shadowmask_lights`. docs/probes.md describes it."""
    arrays = {"format": np.array(FORMAT), "grids": np.array([g.name for g in grids], dtype=str)}
    for i, g in enumerate(grids):
        arrays.update({
            f"{i}.matrix": g.matrix, f"{i}.resolution": np.array(g.resolution, dtype=np.int32),
            f"{i}.index": g.index, f"{i}.valid": g.valid, f"{i}.offset": g.offset.astype(np.float32),
            f"{i}.coefficients": g.coefficients.astype(np.float32),
            f"{i}.occlusion": g.occlusion.astype(np.float32),
            f"{i}.shadowmask_lights": np.array(g.shadowmask_lights, dtype=str),
        })
    with open(path, "wb") as handle:
        np.savez_compressed(handle, **arrays)


def load(path: Path) -> list[ProbeGrid]:
    """The grids `save` wrote."""
    with np.load(path, allow_pickle=False) as data:
        if str(data["format"]) != FORMAT:
            raise ValueError(f"{path}: not a {FORMAT} file")
        return [ProbeGrid(
            name=str(name), matrix=data[f"{i}.matrix"], resolution=tuple(data[f"{i}.resolution"]),
            index=data[f"{i}.index"], valid=data[f"{i}.valid"], offset=data[f"{i}.offset"],
            coefficients=data[f"{i}.coefficients"], occlusion=data[f"{i}.occlusion"],
            shadowmask_lights=tuple(str(s) for s in data[f"{i}.shadowmask_lights"]),
        ) for i, name in enumerate(data["grids"])]
