"""The bake pipeline: scene → photons → texels → estimator → images, one entry point for every
front end (CLI, Blender operator, tests).

`compute` does the long work and reports through `progress(Progress)`; it checks `cancel()` between
photon batches and between estimator chunks, so a cancel lands within a batch's time (well under
a second at the default batch size on two cores). `write` puts files in place only once all of them
exist, so an interrupted bake never leaves half a set of lightmaps.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from . import __version__, estimators, images, texels as texels_mod
from .errors import BakeCancelled, BakeError
from .estimators import EstimatorSettings
from .photons import PhotonTracer, TraceStats
from .scene import Scene

MAX_PHOTONS = 1_000_000_000
MAX_RESOLUTION = 16384
MAX_BOUNCES = 1024
HIT_BYTES = 52  # one stored photon-map hit: position, direction, flux, normal (float32), triangle


@dataclass
class BakeSettings:
    estimator: str = "disc_index"
    photons: int = 1_000_000
    bounces: Optional[int] = None  # None: the scene's own Cycles diffuse bounces
    seed: int = 0
    resolution: int = 128  # default per-object lightmap size (objects may override)
    margin: int = 16  # dilation, pixels
    formats: tuple = ("exr",)
    half: bool = False
    threads: int = 0  # 0: all cores
    batch_size: int = 100_000
    memory_budget_mb: int = 0  # 0: no limit; the photon map keeps every hit (DETP streams)
    estimator_settings: EstimatorSettings = field(default_factory=EstimatorSettings)

    def validate(self) -> None:
        """Raise BakeError naming the first setting that cannot work."""
        def bad(setting, value, why):
            raise BakeError(f"setting '{setting}' = {value!r}: {why}")
        if self.estimator not in estimators.names():
            bad("estimator", self.estimator, f"choose one of {', '.join(estimators.names())}")
        if not isinstance(self.photons, (int, np.integer)) or not 1 <= self.photons <= MAX_PHOTONS:
            bad("photons", self.photons, f"must be between 1 and {MAX_PHOTONS:,}")
        if self.bounces is not None and not 0 <= self.bounces <= MAX_BOUNCES:
            bad("bounces", self.bounces, f"must be between 0 and {MAX_BOUNCES}")
        if not 1 <= self.resolution <= MAX_RESOLUTION:
            bad("resolution", self.resolution, f"must be between 1 and {MAX_RESOLUTION}")
        if not 0 <= self.margin <= 4096:
            bad("margin", self.margin, "must be between 0 and 4096 pixels")
        unknown = [f for f in self.formats if f not in images.WRITERS]
        if unknown or not self.formats:
            bad("formats", self.formats, f"choose from {', '.join(images.WRITERS)}")
        if self.threads < 0:
            bad("threads", self.threads, "must be 0 (all cores) or more")
        if self.batch_size < 1:
            bad("batch_size", self.batch_size, "must be positive")
        if self.memory_budget_mb < 0:
            bad("memory_budget_mb", self.memory_budget_mb, "must be 0 (no limit) or more")
        es = self.estimator_settings
        if es.k < 2:
            bad("k", es.k, "the photon map needs at least 2 neighbours")
        if es.radius is not None and not es.radius > 0:
            bad("radius", es.radius, "must be positive (metres)")
        if not es.radius_texels > 0:
            bad("radius_texels", es.radius_texels, "must be positive")
        if not 0.05 <= es.q <= 0.95:
            bad("q", es.q, "the sphere cache ratio must lie between 0.05 and 0.95")
        if es.kernel not in ("constant", "epanechnikov"):
            bad("kernel", es.kernel, "choose constant or epanechnikov")


@dataclass
class Progress:
    """A typed progress event: `phase` is trace, estimate or write; `fraction` of that phase."""
    phase: str
    fraction: float
    message: str


@dataclass
class BakeResult:
    settings: BakeSettings
    bounces: int
    images: dict  # object name -> (H, W, 3) float32 E/π, dilated, row 0 at the bottom
    masks: dict  # object name -> (H, W) bool, texels covered by the object's UVs
    centre_masks: dict  # object name -> (H, W) bool, texels whose centre lies on a UV triangle
    texels: texels_mod.TexelSet
    value: np.ndarray  # (N, 3) E/π per texel, before dilation
    stats: TraceStats
    counters: dict
    seconds: dict
    files: dict = field(default_factory=dict)  # object name -> [paths]

    def report(self) -> dict:
        st = self.stats
        settings = asdict(self.settings)
        settings["formats"] = list(self.settings.formats)
        settings["bounces"] = self.bounces
        return {
            "version": __version__,
            "settings": settings,
            "objects": [{"name": lm.name, "resolution": [lm.width, lm.height], "texels": lm.count,
                         "texel_size": lm.texel_size, "files": self.files.get(lm.name, [])}
                        for lm in self.texels.lightmaps],
            "photons": st.photons,
            "segments": st.segments,
            "hits": st.hits,
            "rays": st.rays,
            "flux": {"emitted": st.emitted.tolist(), "absorbed": st.absorbed.tolist(),
                     "escaped": st.escaped.tolist(), "truncated": st.truncated.tolist()},
            "estimator": {"name": self.settings.estimator, **self.counters},
            "seconds": self.seconds,
        }


def _cancel_fn(cancel) -> Callable[[], bool]:
    if cancel is None:
        return lambda: False
    if hasattr(cancel, "is_set"):
        return cancel.is_set
    return cancel


def compute(scene: Scene, settings: BakeSettings, progress: Optional[Callable[[Progress], None]] = None,
            cancel=None) -> BakeResult:
    """Trace, estimate and dilate; nothing touches the disk. Raises BakeError or BakeCancelled."""
    return compute_many(scene, settings, [settings.estimator], progress, cancel)[settings.estimator]


def compute_many(scene: Scene, settings: BakeSettings, names, progress: Optional[Callable[[Progress], None]] = None,
                 cancel=None) -> dict:
    """Like `compute`, for several estimators fed the very same photons: every batch goes to each
    of them as it is traced. Returns {estimator name: BakeResult}."""
    names = list(dict.fromkeys(names))
    for name in names:
        replace(settings, estimator=name).validate()
    scene.check()
    report = progress or (lambda p: None)
    cancelled = _cancel_fn(cancel)
    bounces = scene.default_bounces if settings.bounces is None else int(settings.bounces)
    for obj in scene.objects:
        if obj.bake and obj.resolution <= 0:
            obj.resolution = settings.resolution
    tracer = PhotonTracer(scene, settings.photons, bounces, settings.seed,
                          settings.batch_size, settings.threads)
    t0 = time.perf_counter()
    texels = texels_mod.rasterise(scene)
    rasterise_seconds = time.perf_counter() - t0

    def estimate_progress(fraction):
        if cancelled():
            raise BakeCancelled()
        report(Progress("estimate", fraction, f"Estimating {100 * fraction:.0f} %"))

    mean_albedo = float(np.clip(scene.albedo.mean(), 0.0, 0.999)) if scene.triangle_count else 0.0
    expected_segments = int(tracer.photons * sum(mean_albedo ** b for b in range(min(bounces, 64) + 1)))
    clearance = None
    if any(name != "photon_map" for name in names):
        from .estimators.discs import SLAB, disc_radius
        radius = disc_radius(texels, settings.estimator_settings)
        clearance = texels_mod.tangent_clearance(texels, scene.positions, radius, 0.5 * SLAB * radius)
    context = estimators.Context(scene_radius=tracer.escape_radius, expected_segments=expected_segments,
                                 clearance=clearance)
    stored_mb = expected_segments * HIT_BYTES / 1e6
    if "photon_map" in names and settings.memory_budget_mb and stored_mb > settings.memory_budget_mb:
        raise BakeError(f"the photon map would keep about {stored_mb:,.0f} MB of photon hits, over the memory "
                        f"budget of {settings.memory_budget_mb:,} MB: use a DETP estimator (they stream "
                        "photons) or fewer photons")
    runs = {name: estimators.create(name, texels, settings.estimator_settings, estimate_progress, context)
            for name in names}
    spent = {name: 0.0 for name in names}
    total = tracer.photons
    for batch in tracer.batches(cancelled):
        for name, est in runs.items():
            t1 = time.perf_counter()
            est.add(batch)
            spent[name] += time.perf_counter() - t1
        done = tracer.stats.photons
        report(Progress("trace", done / total, f"Tracing {_si(done)}/{_si(total)} photons"))
        if cancelled():
            raise BakeCancelled()
    estimate_progress(0.0)
    results = {}
    for name, est in runs.items():
        t1 = time.perf_counter()
        out = est.finish()
        spent[name] += time.perf_counter() - t1
        seconds = {"rasterise": rasterise_seconds, "trace": tracer.stats.seconds, "estimate": spent[name]}
        results[name] = _finish(replace(settings, estimator=name), bounces, texels, out, tracer, seconds)
    return results


def _finish(settings, bounces, texels, est, tracer, seconds) -> BakeResult:
    """E/π per texel (Cycles' Diffuse bake unit, DIRECT+INDIRECT, no COLOR), as dilated images."""
    value = est.irradiance / np.pi
    result_images, masks, centre_masks = {}, {}, {}
    for lm in texels.lightmaps:
        pixel = texels.pixel[lm.texels]
        img, mask = texels_mod.to_image(value[lm.texels], lm, pixel)
        result_images[lm.name] = texels_mod.dilate(img, mask, settings.margin)
        masks[lm.name] = mask
        centre_masks[lm.name] = np.zeros_like(mask)
        centre_masks[lm.name].flat[pixel[texels.centre_inside[lm.texels]]] = True
    return BakeResult(settings, bounces, result_images, masks, centre_masks, texels, value, tracer.stats,
                      est.counters, seconds)


def output_paths(result: BakeResult, out_dir: Path) -> dict:
    return {name: [out_dir / f"{images.file_stem(name)}.{result.settings.estimator}.{fmt}"
                   for fmt in result.settings.formats] for name in result.images}


def write(result: BakeResult, out_dir: str | os.PathLike,
          progress: Optional[Callable[[Progress], None]] = None, cancel=None) -> Path:
    """Write every lightmap and report.json; files appear together or not at all (a cancel
    before the last file is staged removes the staged ones)."""
    t0 = time.perf_counter()
    cancelled = _cancel_fn(cancel)
    out = images.check_writable_dir(out_dir)
    report = progress or (lambda p: None)
    paths = output_paths(result, out)
    staged = []
    try:
        for i, (name, targets) in enumerate(paths.items()):
            for target in targets:
                fmt = target.suffix[1:]
                tmp = target.with_name(f".{target.stem}.partial{target.suffix}")
                if fmt == "exr":
                    images.write_exr(tmp, result.images[name], half=result.settings.half)
                else:
                    images.WRITERS[fmt](tmp, result.images[name])
                staged.append((tmp, target))
            report(Progress("write", (i + 1) / len(paths), f"Writing {name}"))
            if cancelled():
                raise BakeCancelled()
        for tmp, target in staged:
            os.replace(tmp, target)
    except BaseException:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        raise
    result.files = {name: [str(p) for p in targets] for name, targets in paths.items()}
    result.seconds["write"] = time.perf_counter() - t0
    report_path = out / "report.json"
    tmp = out / ".report.partial.json"
    tmp.write_text(json.dumps(result.report(), indent=2))
    os.replace(tmp, report_path)
    return report_path


def bake(scene: Scene, settings: BakeSettings, out_dir: str | os.PathLike,
         progress: Optional[Callable[[Progress], None]] = None, cancel=None,
         export_seconds: float = 0.0) -> BakeResult:
    """Check the output folder first, then compute and write."""
    settings.validate()
    images.check_writable_dir(out_dir)
    result = compute(scene, settings, progress, cancel)
    result.seconds["export"] = export_seconds
    write(result, out_dir, progress)
    return result


def _si(n: int) -> str:
    for div, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if n >= div:
            return f"{n / div:.3g}{suffix}"
    return str(n)
