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
from functools import partial
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from . import __version__, denoise as denoise_mod, direct as direct_mod, estimators, images, memory, \
    texels as texels_mod
from .errors import BakeCancelled, BakeError
from .noise import MIN_GROUPS, BatchNoise
from .estimators import EstimatorSettings
from .estimators.discs import SLAB, disc_radius
from .photons import PhotonTracer, RayCaster, TraceStats
from .scene import Scene

MAX_PHOTONS = 1_000_000_000
MAX_RESOLUTION = 16384
MAX_BOUNCES = 1024
DIRECT_MODES = ("sampled", "photons")
MAX_DIRECT_SAMPLES = 4096


@dataclass
class BakeSettings:
    estimator: str = "disc_index"
    photons: int = 1_000_000
    # sampled: direct light by shadow rays at every texel, the estimator sees indirect light only;
    # photons: the estimator sees every segment (the paper's experiments).
    direct: str = "sampled"
    direct_samples: int = direct_mod.DEFAULT_SAMPLES  # shadow rays per texel and light with extent
    bounces: Optional[int] = None  # None: the scene's own Cycles diffuse bounces
    seed: int = 0
    resolution: int = 128  # default per-object lightmap size (objects may override)
    margin: int = 16  # dilation, pixels
    formats: tuple = ("exr",)
    half: bool = False
    threads: int = 0  # 0: all cores
    batch_size: int = 100_000
    memory_budget_mb: int = 0  # 0: no limit; the photon map keeps every hit (DETP streams)
    # Stop tracing early (photons is then the most to trace): once every lightmap's relative noise
    # is at most target_noise per cent, or before time_limit seconds of tracing and estimating.
    target_noise: float = 0.0
    time_limit: float = 0.0
    denoise: bool = True  # OIDN on every lightmap (chart-aware; denoise.py), when pyoidn is installed
    keep_raw: bool = False  # also write the lightmaps as they were before denoising (<name>.<estimator>.raw.exr)
    estimator_settings: EstimatorSettings = field(default_factory=EstimatorSettings)

    def validate(self) -> None:
        """Raise BakeError naming the first setting that cannot work."""
        def bad(setting, value, why):
            raise BakeError(f"setting '{setting}' = {value!r}: {why}")
        if self.estimator not in estimators.names():
            bad("estimator", self.estimator, f"choose one of {', '.join(estimators.names())}")
        if not isinstance(self.photons, (int, np.integer)) or not 1 <= self.photons <= MAX_PHOTONS:
            bad("photons", self.photons, f"must be between 1 and {MAX_PHOTONS:,}")
        if self.direct not in DIRECT_MODES:
            bad("direct", self.direct, f"choose one of {', '.join(DIRECT_MODES)}")
        if not isinstance(self.direct_samples, (int, np.integer)) or \
                not 1 <= self.direct_samples <= MAX_DIRECT_SAMPLES:
            bad("direct_samples", self.direct_samples, f"must be between 1 and {MAX_DIRECT_SAMPLES}")
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
        if not (np.isfinite(self.target_noise) and 0.0 <= self.target_noise <= 100.0):
            bad("target_noise", self.target_noise, "must be a percentage between 0 (off) and 100")
        fixed = estimators.get(self.estimator).fixed_noise(self.estimator_settings)
        if self.target_noise and fixed is not None:
            bad("target_noise", self.target_noise, f"the {self.estimator} estimator's noise does not fall with "
                f"more photons (about {100 * fixed:.2g} % whatever the count): use a DETP estimator")
        if not (np.isfinite(self.time_limit) and self.time_limit >= 0.0):
            bad("time_limit", self.time_limit, "must be 0 (off) or a number of seconds")
        if self.memory_budget_mb < 0:
            bad("memory_budget_mb", self.memory_budget_mb, "must be 0 (no limit) or more")
        es = self.estimator_settings
        if es.k < 2:
            bad("k", es.k, "the photon map needs at least 2 neighbours")
        if es.radius is not None and not (np.isfinite(es.radius) and es.radius > 0):
            bad("radius", es.radius, "must be a positive, finite number of metres")
        if es.radius_texels is not None and not (np.isfinite(es.radius_texels) and es.radius_texels > 0):
            bad("radius_texels", es.radius_texels, "must be a positive, finite number of texels")
        if not 0.05 <= es.q <= 0.95:
            bad("q", es.q, "the sphere cache ratio must lie between 0.05 and 0.95")
        if es.kernel not in estimators.KERNELS:
            bad("kernel", es.kernel, f"choose {' or '.join(estimators.KERNELS)}")


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
    images: dict  # object name -> (H, W, 3) float32 E/π, denoised (if asked) and dilated, row 0 at the bottom
    masks: dict  # object name -> (H, W) bool, texels covered by the object's UVs
    centre_masks: dict  # object name -> (H, W) bool, texels whose centre lies on a UV triangle
    texels: texels_mod.TexelSet
    value: np.ndarray  # (N, 3) E/π per texel, before dilation
    stats: TraceStats
    counters: dict
    seconds: dict
    files: dict = field(default_factory=dict)  # object name -> [paths]
    direct: dict = field(default_factory=dict)  # how direct light was found (report.json)
    noise: dict = field(default_factory=dict)  # object name -> relative noise of its lightmap
    memory: dict = field(default_factory=dict)  # the estimate made before work, and the peak used
    export: dict = field(default_factory=dict)  # what the exporter found (instances, triangles, textures, …)
    raw_images: dict = field(default_factory=dict)  # object name -> image before denoising (when denoised)
    warnings: list = field(default_factory=list)
    stopped_by: str = "photons"  # photons (all traced), target_noise, time_limit, user (Stop and keep)
    share: float = 1.0  # the share of the photons traced (less than 1 when stopped early)

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
            "photons_hit": st.photons_hit,  # photons that met the scene at all
            "alpha": {"passes": st.alpha_passes, "cut": st.alpha_cut},
            "rays": st.rays,
            "flux": {"emitted": st.emitted.tolist(), "absorbed": st.absorbed.tolist(),
                     "escaped": st.escaped.tolist(), "truncated": st.truncated.tolist()},
            "estimator": {"name": self.settings.estimator, **self.counters},
            "direct": self.direct,
            "noise": {name: round(100.0 * v, 3) for name, v in self.noise.items()},  # per cent
            "stopped_by": self.stopped_by,
            "memory": self.memory,
            "export": self.export,
            "denoised": bool(self.raw_images),
            "warnings": list(self.warnings),
            "seconds": self.seconds,
        }


@dataclass
class Partial:
    """The bake so far, after a batch, for a live preview: `read()` returns the primary
    estimator's current estimate of the whole bake, E/π per texel (N, 3), direct light included
    (the sums so far over the share traced, as an early stop would keep them)."""
    estimator: str
    photons: int
    share: float
    noise: Optional[float]  # the worst lightmap's relative noise so far, when measured
    texels: texels_mod.TexelSet
    read: Callable[[], np.ndarray]


def preview_images(texels: texels_mod.TexelSet, value: np.ndarray, margin: int) -> dict:
    """{object name: (H, W, 3) float32 image, dilated, row 0 at the bottom} of per-texel values."""
    out = {}
    for lm in texels.lightmaps:
        img, mask = texels_mod.to_image(value[lm.texels], lm, texels.pixel[lm.texels])
        out[lm.name] = texels_mod.dilate(img, mask, margin).astype(np.float32, copy=False)
    return out


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
                 cancel=None, stop=None, preview: Optional[Callable[[Partial], None]] = None) -> dict:
    """Like `compute`, for several estimators fed the very same photons: every batch goes to each
    of them as it is traced. Returns {estimator name: BakeResult}. `settings.threads` (0: all
    cores) holds for tracing, shadow rays and the compiled estimators alike. `stop()` true ends
    tracing after the batch, keeping what there is as a finished bake (stopped_by "user");
    `preview` sees the bake after every batch (Partial)."""
    import numba
    before = numba.get_num_threads()
    if settings.threads:
        numba.set_num_threads(max(1, min(int(settings.threads), numba.config.NUMBA_NUM_THREADS)))
    try:
        return _compute_many(scene, settings, names, progress, cancel, stop, preview)
    finally:
        numba.set_num_threads(before)


def _compute_many(scene, settings, names, progress, cancel, stop=None, preview=None) -> dict:
    names = list(dict.fromkeys(names))
    if settings.estimator_settings.radius_texels is None:
        texels_wide = estimators.RADIUS_TEXELS_INDIRECT if settings.direct == "sampled" else estimators.RADIUS_TEXELS_ALL
        settings = replace(settings, estimator_settings=replace(settings.estimator_settings, radius_texels=texels_wide))
    for name in names:
        replace(settings, estimator=name).validate()
    scene.check()
    report = progress or (lambda p: None)
    cancelled = _cancel_fn(cancel)
    t_start = time.perf_counter()  # the time limit counts the whole bake
    bounces = scene.default_bounces if settings.bounces is None else int(settings.bounces)
    for obj in scene.objects:
        if obj.bake and obj.resolution <= 0:
            obj.resolution = settings.resolution
    sampled = settings.direct == "sampled"
    first = 1 if sampled else 0  # the first flight is direct light, left out when sampled
    survival = float(np.mean(np.clip(scene.albedo, 0.0, 1.0).max(axis=1))) if scene.triangle_count else 0.0
    per_photon = memory.segments_per_photon(survival, bounces)
    per_photon_kept = memory.segments_per_photon(survival, bounces, first)
    batch_size = memory.batch_photons(settings.batch_size, per_photon)
    need = _check_memory(scene, settings, names, batch_size, per_photon, per_photon_kept)
    t0 = time.perf_counter()
    texels = texels_mod.rasterise(scene)
    rasterise_seconds = time.perf_counter() - t0
    # DETP discs reach past a surface's edge by their radius and count what passes there: sun
    # photons must start that far beyond the footprint of the geometry too.
    discs = any(estimators.get(name).discs for name in names)
    radius = disc_radius(texels, settings.estimator_settings) if discs else None
    reach = float(np.max(radius)) if discs and len(texels) else 0.0
    caster = RayCaster(scene.positions)
    tracer = PhotonTracer(scene, settings.photons, bounces, settings.seed, batch_size, settings.threads,
                          indirect_only=sampled, caster=caster, margin=reach)
    direct_e, direct_info = None, {"mode": settings.direct}
    if sampled:
        def direct_progress(fraction):
            if cancelled():
                raise BakeCancelled()
            report(Progress("direct", fraction, f"Direct light {100 * fraction:.0f} %"))
        direct_e, info = direct_mod.direct_irradiance(scene, texels, caster, settings.direct_samples,
                                                      settings.seed, tracer.threads, direct_progress, cancelled)
        direct_info.update(info)

    def estimate_progress(fraction):
        if cancelled():
            raise BakeCancelled()
        report(Progress("estimate", fraction, f"Estimating {100 * fraction:.0f} %"))

    expected_segments = int(tracer.photons * per_photon_kept)
    clearance = None
    t0 = time.perf_counter()
    if discs:
        report(Progress("prepare", 0.0, "Measuring disc clearance"))
        clearance = texels_mod.tangent_clearance(texels, scene.positions, radius, 0.5 * SLAB * radius)
    clearance_seconds = time.perf_counter() - t0
    context = estimators.Context(scene_radius=tracer.escape_radius, expected_segments=expected_segments,
                                 clearance=clearance)
    runs, build = {}, {}
    for name in names:
        report(Progress("prepare", 0.5, f"Preparing {name}"))
        t1 = time.perf_counter()
        runs[name] = estimators.create(name, texels, settings.estimator_settings, estimate_progress, context)
        build[name] = time.perf_counter() - t1
    spent = {name: 0.0 for name in names}
    # Noise from the spread between groups of batches, for the estimators that stream (a group
    # closes once an estimator has consumed everything it was given).
    noise = {name: BatchNoise(len(texels)) for name, est in runs.items() if est.streaming}
    since = {name: 0 for name in noise}  # segments since each one's last reading
    primary = names[0]
    total = tracer.photons
    stopped_by = "photons"
    current = {}
    for batch in tracer.batches(cancelled):
        t_batch = time.perf_counter()
        for name, est in runs.items():
            t1 = time.perf_counter()
            est.add(batch)
            if name in noise:
                since[name] += batch.segment_count
                if since[name] >= min(est.group_segments, expected_segments // 16):
                    noise[name].update(est.finish().irradiance, tracer.share)
                    since[name] = 0
            spent[name] += time.perf_counter() - t1
        done = tracer.stats.photons
        message = f"Tracing {_si(done)}/{_si(total)} photons"
        if primary in noise and noise[primary].groups >= 2:
            direct_now = 0.0 if direct_e is None else direct_e
            current = noise[primary].relative(texels.lightmaps, direct_now + noise[primary].previous[:, None] /
                                              max(tracer.share, 1e-300))
            message += f" · noise {100 * max(current.values(), default=0.0):.2g} %"
        report(Progress("trace", done / total, message))
        if cancelled():
            raise BakeCancelled()
        if preview is not None and runs[primary].streaming:
            preview(Partial(primary, done, tracer.share, max(current.values(), default=None), texels,
                            partial(_partial_value, runs[primary], direct_e, tracer.share)))
        if stop is not None and tracer.share < 1.0 and stop():
            stopped_by = "user"
            break
        elapsed = time.perf_counter() - t_start
        if settings.time_limit and elapsed + (time.perf_counter() - t_batch) > settings.time_limit:
            stopped_by = "time_limit"
            break
        if settings.target_noise and noise.get(primary) is not None and noise[primary].groups >= MIN_GROUPS \
                and max(current.values(), default=0.0) * 100 <= settings.target_noise:
            stopped_by = "target_noise"
            break
    share = tracer.share
    estimate_progress(0.0)
    results = {}
    for name, est in runs.items():
        t1 = time.perf_counter()
        out = est.finish()
        if name in noise and since[name] > 0:
            noise[name].update(out.irradiance, share)
        if share < 1.0:  # stopped early: the batches so far stand for the whole bake
            out.irradiance = out.irradiance / share
        spent[name] += time.perf_counter() - t1
        seconds = {"rasterise": rasterise_seconds, "direct": direct_info.get("seconds", 0.0),
                   "clearance": clearance_seconds, "build": build[name], "trace": tracer.stats.seconds,
                   "estimate": spent[name]}
        result = _finish(replace(settings, estimator=name), bounces, texels, out, tracer, seconds,
                         direct_e, direct_info)
        result.stopped_by = stopped_by
        result.share = share
        result.export = dict(getattr(scene, "export_stats", None) or {})
        result.memory = {"estimate_mb": round(need.total / 1e6, 1),
                         "parts_mb": {k: round(v / 1e6, 1) for k, v in need.parts.items()},
                         "peak_mb": round(memory.peak_bytes() / 1e6, 1), "batch_photons": batch_size}
        if name in noise:
            result.noise = noise[name].relative(texels.lightmaps, result.value * np.pi)
        elif runs[name].fixed_noise(settings.estimator_settings) is not None:
            fixed = runs[name].fixed_noise(settings.estimator_settings)
            result.noise = {lm.name: fixed for lm in texels.lightmaps}
        results[name] = result
    return results


def _partial_value(est, direct_e, share) -> np.ndarray:
    irradiance = est.finish().irradiance / share
    return (irradiance if direct_e is None else irradiance + direct_e) / np.pi


def _finish(settings, bounces, texels, est, tracer, seconds, direct_e=None, direct_info=None) -> BakeResult:
    """E/π per texel (Cycles' Diffuse bake unit, DIRECT+INDIRECT, no COLOR), as dilated images."""
    irradiance = est.irradiance if direct_e is None else est.irradiance + direct_e
    value = irradiance / np.pi
    result_images, raw_images, masks, centre_masks = {}, {}, {}, {}
    warnings = []
    denoise = settings.denoise and denoise_mod.available()
    if settings.denoise and not denoise:
        warnings.append("lightmaps not denoised: the pyoidn package is not installed")
    t0 = time.perf_counter()
    for lm in texels.lightmaps:
        pixel = texels.pixel[lm.texels]
        img, mask = texels_mod.to_image(value[lm.texels], lm, pixel)
        raw = texels_mod.dilate(img, mask, settings.margin)
        if denoise:
            raw_images[lm.name] = raw
            result_images[lm.name] = denoise_mod.denoise_lightmap(img, mask, margin=settings.margin)
        else:
            result_images[lm.name] = raw
        masks[lm.name] = mask
        centre_masks[lm.name] = np.zeros_like(mask)
        centre_masks[lm.name].flat[pixel[texels.centre_inside[lm.texels]]] = True
    if denoise:
        seconds["denoise"] = time.perf_counter() - t0
    return BakeResult(settings, bounces, result_images, masks, centre_masks, texels, value, tracer.stats,
                      est.counters, seconds, direct=dict(direct_info or {}), raw_images=raw_images,
                      warnings=warnings)


def _check_memory(scene, settings, names, batch, per_photon, per_photon_kept) -> memory.Estimate:
    """The bake's peak memory, estimated before any work; over the budget (the setting, else 80 %
    of what the system has free) it is a BakeError that says what to lower."""
    pixels = sum(o.resolution * o.resolution for o in scene.objects if o.bake)
    per_texel = {n: estimators.get(n).bytes_per_texel for n in names}
    hits = int(settings.photons * per_photon_kept) if any(estimators.get(n).stores_hits for n in names) else 0
    geometry = scene.positions.nbytes + scene.normals.nbytes + scene.uvs.nbytes + 24 * scene.triangle_count
    need = memory.estimate(pixels, per_texel, batch, per_photon, per_photon_kept,
                           settings.threads or os.cpu_count() or 1, hits, geometry)
    budget = settings.memory_budget_mb * 1e6 if settings.memory_budget_mb else 0.8 * memory.available_bytes()
    if budget and need.total > budget:
        advice = []
        if hits and need.parts.get("photon map hits", 0) > 0.3 * need.total:
            advice.append("a DETP estimator (they stream photons) or fewer photons")
        if need.parts["texels"] + need.parts["lightmap images"] > 0.3 * need.total:
            advice.append("a lower resolution")
        if need.parts["photon batches"] + need.parts["stream logs"] > 0.3 * need.total:
            advice.append("fewer bounces or a smaller batch")
        raise BakeError(f"this bake would need about {need.total / 1e9:,.1f} GB of memory (the most: "
                        f"{need.biggest()}), over the budget of {budget / 1e9:,.1f} GB"
                        f"{' (the memory budget preference)' if settings.memory_budget_mb else ' (80 % of free memory)'}"
                        f": use {' or '.join(advice) or 'a smaller bake'}")
    return need


def output_paths(result: BakeResult, out_dir: Path) -> dict:
    stems = images.file_stems(result.images)
    out = {name: [out_dir / f"{stems[name]}.{result.settings.estimator}.{fmt}"
                  for fmt in result.settings.formats] for name in result.images}
    if result.settings.keep_raw and result.raw_images:
        for name, paths in out.items():
            paths.append(out_dir / f"{stems[name]}.{result.settings.estimator}.raw.exr")
    return out


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
                picture = result.raw_images[name] if target.name.endswith(".raw.exr") else result.images[name]
                if fmt == "exr":
                    images.write_exr(tmp, picture, half=result.settings.half)
                else:
                    images.WRITERS[fmt](tmp, picture)
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
