"""What a bake hands back: progress events (Progress), the finished result and its report
(BakeResult), the live preview's snapshot (Snapshot), and the small helpers every stage of the
run shares (a cancel callable, counts in words)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Callable, Optional

import numpy as np

from .. import __version__
from ..lightmap import dilation, texels as texels_mod
from ..transport.photons import TraceStats
from .settings import BakeSettings


@dataclass
class Progress:
    """A typed progress event: `phase` is trace, estimate or write; `fraction` of that phase;
    `part` (k, n) when the phase belongs to the k-th of n parts of one job (a range's frames)."""
    phase: str
    fraction: float
    message: str
    part: Optional[tuple] = None


class RawImages(Mapping):
    """object name -> a lightmap's image before denoising, made when asked from the bake's
    per-texel values (dilated by `margin`, as the denoised image is): a bake keeps no second
    full-size image per lightmap for the few callers that want the raw one (keep_raw, tests)."""

    def __init__(self, texels, value: np.ndarray, margin: int, names):
        self._texels, self._value, self._margin = texels, value, margin
        self._names = [lm.name for lm in texels.lightmaps if lm.name in set(names)]

    def __getitem__(self, name: str) -> np.ndarray:
        lm = next((lm for lm in self._texels.lightmaps if lm.name == name and name in self._names), None)
        if lm is None:
            raise KeyError(name)
        img, mask = texels_mod.to_image(self._value[lm.texels], lm, self._texels.pixel[lm.texels])
        return dilation.dilate(img, mask, self._margin, in_place=True)

    def __iter__(self):
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


# What a measured noise is: the spread between blocks of batches (lightmap/noise.py).
NOISE_UNIT = "per cent of the mean irradiance over every baked texel (RMS over each lightmap's texels)"


@dataclass
class BakeResult:
    settings: BakeSettings
    bounces: int
    images: dict  # object name -> (H, W, 3) float32 E/π, denoised (if asked) and dilated, row 0 at the bottom
    masks: dict  # object name -> (H, W) bool, texels covered by the object's UVs
    # object name -> (H, W) bool, texels baked at their centre as Cycles bakes them: the centre lies on
    # a UV triangle and was not moved out from under other geometry (validity.py)
    centre_masks: dict
    texels: texels_mod.TexelSet
    value: np.ndarray  # (N, 3) float32 E/π per texel, before dilation
    stats: TraceStats
    counters: dict
    seconds: dict
    files: dict = field(default_factory=dict)  # object name -> [paths]
    direct: dict = field(default_factory=dict)  # how direct light was found (report.json)
    noise: dict = field(default_factory=dict)  # object name -> relative noise of its lightmap, when measured
    noise_unmeasured: str = ""  # why `noise` is empty: report.json then holds null and this reason
    noise_unit: str = NOISE_UNIT  # what the noise is relative to
    memory: dict = field(default_factory=dict)  # the estimate made before work, and the peak used
    export: dict = field(default_factory=dict)  # what the exporter found (instances, triangles, textures, …)
    raw_images: dict = field(default_factory=dict)  # object name -> image before denoising (when denoised)
    # --directional: object name -> (H, W, 9) L1 or (H, W, 4) direction map (run/directional.py), and
    # what report.json says of it (mode, channel names, clamped texels)
    l1_images: dict = field(default_factory=dict)
    directional: dict = field(default_factory=dict)
    # --shadowmask: object name -> (H, W, 4) visibility of the masked lights, one per channel in the
    # order of shadowmask["lights"] (unused channels 1), and what report.json says of it
    shadowmask_images: dict = field(default_factory=dict)
    shadowmask: dict = field(default_factory=dict)
    cluster: dict = field(default_factory=dict)  # where the photons were traced when not here (distributed.py)
    warnings: list = field(default_factory=list)
    stopped_by: str = "photons"  # photons (all traced), target_noise, time_limit, user (Stop and keep)
    share: float = 1.0  # the share of the photons traced (less than 1 when stopped early)
    # A bake into a folder with an earlier one (incremental.py): each baked object's key, the
    # objects whose earlier lightmaps were kept (name -> that bake's report entry), and the entries
    # of objects not in this bake whose files are still there.
    keys: dict = field(default_factory=dict)
    reused: dict = field(default_factory=dict)
    earlier: list = field(default_factory=list)
    # Light probes (probes/): the grids baked with this result (the primary estimator's), and what
    # report.json says of them (count, invalid, moved, seconds)
    probes: list = field(default_factory=list)
    probe_info: dict = field(default_factory=dict)
    probe_file: str = ""  # where writing.py put them

    def noise_percent(self) -> dict:
        """{lightmap name: noise in per cent, or None where it was not measured}, for JSON."""
        return {lm.name: round(100.0 * self.noise[lm.name], 3) if lm.name in self.noise else None
                for lm in self.texels.lightmaps}

    def _entries(self, lm) -> list:
        """report.json's entries of lightmap `lm`: its object's, or one per object of an atlas
        (`image` names the atlas, `rect` where the object's charts lie in it)."""
        common = {"resolution": [lm.width, lm.height], "files": self.files.get(lm.name, []),
                  "charts": {"count": lm.charts, "median_width": round(lm.chart_width, 2),
                             "border": round(lm.border, 4)}}
        if not lm.placement:
            return [{"name": lm.name, "texels": lm.count, "texel_size": lm.texel_size, **common,
                     **({"key": self.keys[lm.name], "reused": False} if lm.name in self.keys else {})}]
        return [{"name": name, "image": lm.name, **common, **place,  # its own charts, not the atlas's
                 **({"key": self.keys[name], "reused": False} if name in self.keys else {})}
                for name, place in lm.placement.items()]

    def extra_maps(self) -> list:
        """(file suffix, {object name: image}, channel names) of the maps written beside each
        lightmap: <object>.<estimator>.<suffix>.exr (writing.py)."""
        out = []
        if self.l1_images:
            out.append((self.directional["suffix"], self.l1_images, self.directional.get("file_channels")))
            for a, axis in enumerate(self.directional.get("axis_files", [])):  # RGB, for Blender and engines
                out.append((axis, {name: img[..., 3 * a:3 * a + 3] for name, img in self.l1_images.items()}, None))
        if self.shadowmask_images:
            out.append(("shadowmask", self.shadowmask_images, self.shadowmask["channels"]))
        return out

    def report(self) -> dict:
        st = self.stats
        atlases = [{"name": lm.name, "size": lm.width, "objects": list(lm.placement), "texels": lm.count,
                    "fill": round(lm.count / float(lm.width * lm.height), 4)}
                   for lm in self.texels.lightmaps if lm.placement]
        settings = asdict(self.settings)
        settings["formats"] = list(self.settings.formats)
        settings["bounces"] = self.bounces
        return {
            "version": __version__,
            "settings": settings,
            "objects": [entry for lm in self.texels.lightmaps for entry in self._entries(lm)]
            + [{**entry, "reused": True} for entry in self.reused.values()],
            **({"atlases": atlases} if atlases else {}),
            **({"reused": list(self.reused)} if self.keys else {}),
            **({"earlier_objects": self.earlier} if self.earlier else {}),
            "photons": st.photons,
            "segments": st.segments,
            "hits": st.hits,
            "photons_hit": st.photons_hit,  # photons that met the scene at all
            "alpha": {"passes": st.alpha_passes, "cut": st.alpha_cut},
            "rays": st.rays,
            "flux": {"emitted": st.emitted.tolist(), "absorbed": st.absorbed.tolist(),
                     "escaped": st.escaped.tolist(), "truncated": st.truncated.tolist()},
            "estimator": {"name": self.settings.estimator, **self.counters},
            "direct": self.direct,
            "noise": self.noise_percent(),
            "noise_unit": self.noise_unit,
            **({"noise_unmeasured": self.noise_unmeasured} if None in self.noise_percent().values() else {}),
            "stopped_by": self.stopped_by,
            "memory": self.memory,
            "export": self.export,
            "denoised": bool(self.raw_images),
            **({"directional": self.directional} if self.directional else {}),
            **({"shadowmask": self.shadowmask} if self.shadowmask else {}),
            **({"cluster": self.cluster} if self.cluster else {}),
            **({"probes": {**self.probe_info, "file": self.probe_file}} if self.probe_info else {}),
            "warnings": list(self.warnings),
            "seconds": self.seconds,
        }


@dataclass
class Snapshot:
    """The bake so far, after a block of batches, for a live preview: `read()` returns the primary
    estimator's current estimate of the whole bake, E/π per texel (N, 3), direct light included
    (the batches so far over the share traced, as an early stop would keep them). Read it before
    the next block is added, or not at all: `slow` says reading it costs a gather over every hit
    so far (the photon map), not a copy of sums."""
    estimator: str
    photons: int
    share: float
    noise: Optional[float]  # the worst lightmap's relative noise so far, when measured
    texels: texels_mod.TexelSet
    read: Callable[[], np.ndarray]
    slow: bool = False


def preview_images(texels: texels_mod.TexelSet, value: np.ndarray, margin: int) -> dict:
    """{object name: (H, W, 3) float32 image, dilated, row 0 at the bottom} of per-texel values."""
    out = {}
    for lm in texels.lightmaps:
        img, mask = texels_mod.to_image(value[lm.texels], lm, texels.pixel[lm.texels])
        out[lm.name] = dilation.dilate(img, mask, margin).astype(np.float32, copy=False)
    return out


def cancel_fn(cancel) -> Callable[[], bool]:
    if cancel is None:
        return lambda: False
    if hasattr(cancel, "is_set"):
        return cancel.is_set
    return cancel


def si(n: int) -> str:
    for div, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if n >= div:
            return f"{n / div:.3g}{suffix}"
    return str(n)
