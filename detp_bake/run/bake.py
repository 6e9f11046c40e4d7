"""The bake pipeline: scene → texels → photons → estimators → images. The front ends run it
through a job (job.py); tests and benchmarks call `compute` and `write` directly.

`compute` does the long work and reports through `progress(Progress)`; it checks `cancel()` between
photon batches and between estimator chunks, so a cancel lands within a batch's time (well under
a second at the default batch size on two cores). `write` puts files in place only once all of them
exist, so an interrupted bake never leaves half a set of lightmaps.
"""
from __future__ import annotations

import contextlib
import os
import time
from dataclasses import replace
from functools import partial
from typing import Callable, Optional

import numpy as np

from .. import estimators, options
from ..lightmap import (charts as charts_mod, denoise as denoise_mod, fragments as fragments_mod, images,
    sites as sites_mod, texels as texels_mod, validity)
from ..transport import direct as direct_mod, frame_direct
from . import directional as directional_mod, memory
from ..errors import BakeCancelled
from ..options import AUTO_PHOTONS, PHOTONS_PER_TEXEL
from ..lightmap.noise import MIN_GROUPS, BatchNoise
from ..estimators import EstimatorSettings
from ..estimators.discs import SLAB, capped_radius, disc_radius
from ..estimators.rise import own_surface_rise, piece_extent, welded_pieces
from ..transport.photons import PhotonTracer
from ..rays import RayCaster
from ..scene import Scene
from .batches import Partial, Totals, TraceJob, blocks, trace_batches, worker_bytes  # noqa: F401 (the API)
from .results import BakeResult, Progress, RawImages, Snapshot, cancel_fn, preview_images, si  # noqa: F401 (the API)
from .settings import BakeSettings  # noqa: F401 (the API)
from .writing import warn_stale, write, write_many  # noqa: F401 (the API)
from .finishing import Finishing

# Automatic photon count (photons = 0): PHOTONS_PER_TEXEL for each lightmap texel to bake, within
# AUTO_PHOTONS. At 16 a texel the default (histogram + OIDN) bake of a fully covered lightmap
# lands about 4-8 indirect photons a texel; tracing costs about 0.4 s a million photons on 2 cores.
RAYS_PER_SECOND = 2.0e6  # photon segments traced a second and thread, for the time a bake announces

def compute(scene: Scene, settings: BakeSettings, progress: Optional[Callable[[Progress], None]] = None,
            cancel=None, cluster=None, frame_state: Optional[estimators.FrameState] = None,
            reach_of=None) -> BakeResult:
    """Trace, estimate and dilate; nothing touches the disk. Raises BakeError or BakeCancelled.
    `cluster` (a distributed.Cluster) traces the photons on its workers instead of here.
    `frame_state`: one frame of a range (frames.py), shared by the range's frames. `reach_of`:
    objects whose discs also set how far out sun and sky photons start (`disc_reach`), as if they
    were baked too (incremental.py: a bake that reuses their lightmaps)."""
    return compute_many(scene, settings, [settings.estimator], progress, cancel, cluster,
                        frame_state, reach_of=reach_of)[settings.estimator]


def compute_many(scene: Scene, settings: BakeSettings, names, progress: Optional[Callable[[Progress], None]] = None,
                 cancel=None, cluster=None, frame_state: Optional[estimators.FrameState] = None, stop=None,
                 preview: Optional[Callable[[Snapshot], None]] = None, reach_of=None) -> dict:
    """Like `compute`, for several estimators fed the very same photons: every batch goes to each
    of them as it is traced. Returns {estimator name: BakeResult}. `settings.threads` (0: all
    cores) holds for tracing, shadow rays and the compiled estimators alike. `stop()` true ends
    tracing after the batch, keeping what there is as a finished bake (stopped_by "user");
    `preview` sees the bake after every block of batches (Snapshot), whatever the estimator."""
    import numba
    before = numba.get_num_threads()
    if settings.threads:
        numba.set_num_threads(max(1, min(int(settings.threads), numba.config.NUMBA_NUM_THREADS)))
    try:
        return _compute_many(scene, settings, names, progress, cancel, cluster, frame_state, stop, preview, reach_of)
    finally:
        numba.set_num_threads(before)


def auto_photons(scene: Scene, settings: BakeSettings) -> int:
    """The photons a bake traces: the setting, or when it is 0, PHOTONS_PER_TEXEL for every texel
    of the lightmaps to bake (objects without a resolution of their own take the setting's), within
    AUTO_PHOTONS: more texels need more photons for the same noise per texel."""
    if settings.photons:
        return int(settings.photons)
    texels = sum((o.resolution if o.resolution > 0 else settings.resolution) ** 2 for o in scene.objects if o.bake)
    low, high = AUTO_PHOTONS
    return int(min(max(PHOTONS_PER_TEXEL * texels, low), high))


def _wide(settings: BakeSettings) -> BakeSettings:
    """The settings with the disc radius in texels set from the direct-light mode when unset."""
    if settings.estimator_settings.radius_texels is not None:
        return settings
    texels_wide = options.RADIUS_TEXELS_INDIRECT if settings.direct == "sampled" else options.RADIUS_TEXELS_ALL
    return replace(settings, estimator_settings=replace(settings.estimator_settings, radius_texels=texels_wide))


def _reach(scene: Scene, estimator_settings: EstimatorSettings, names, resolution: int) -> float:
    """The widest disc of objects `names` (a centred scene: the same floats as `rasterise` finds)."""
    if estimator_settings.radius is not None:
        return float(estimator_settings.radius)
    sizes = texels_mod.texel_sizes(scene, names, resolution)
    return max((float(np.float64(size) * float(estimator_settings.radius_texels)) for size in sizes.values()),
               default=0.0)


def disc_reach(scene: Scene, settings: BakeSettings, names) -> float:
    """How far beyond the geometry a bake of objects `names` with a disc estimator starts sun and
    sky photons: its widest disc (0 without discs)."""
    if not estimators.get(settings.estimator).discs:
        return 0.0
    settings = _wide(settings)
    return _reach(scene.recentred()[0], settings.estimator_settings, names, settings.resolution)


def _compute_many(scene, settings, names, progress, cancel, cluster=None, frame_state=None, stop=None,
                  preview=None, reach_of=None) -> dict:
    run = _Pipeline(scene, settings, names, progress, cancel, cluster, frame_state, stop, preview)
    run.texels_and_tracer(reach_of)
    run.direct_light()
    run.estimators()
    run.trace()
    return run.results()


class _Pipeline:
    """One bake, stage by stage (docs/architecture.md): the settings checked and the photons
    chosen; the texels, their validity and the tracer; direct light by shadow rays; the estimators
    and their discs; tracing, batch by batch, with noise, preview and the early stops; then each
    estimator's lightmaps. Each stage leaves what the next needs on the object."""

    def __init__(self, scene, settings, names, progress, cancel, cluster, frame_state, stop, preview):
        memory.return_large_blocks()  # freed arrays go back to the system (glibc)
        memory.reset_peak()  # report.json's peak is this bake's
        self.names = list(dict.fromkeys(names))
        settings = _wide(settings)
        for name in self.names:
            replace(settings, estimator=name).validate()
        directional_mod.check(settings, self.names, frame_state)
        scene.check()
        directional_mod.check_shadowmask(settings, scene, frame_state)
        automatic = not settings.photons
        self.settings = settings = replace(settings, photons=auto_photons(scene, settings))
        self.scene, self.offset = scene.recentred()  # float32 rays and discs work near the origin (scene.py)
        self.report = progress or (lambda p: None)
        self.cancelled = cancel_fn(cancel)
        self.cluster, self.frame_state, self.stop, self.preview = cluster, frame_state, stop, preview
        self.t_start = time.perf_counter()  # the time limit counts the whole bake
        self.bounces = scene.default_bounces if settings.bounces is None else int(settings.bounces)
        for obj in self.scene.objects:
            if obj.bake and obj.resolution <= 0:
                obj.resolution = settings.resolution
        self.sampled = settings.direct == "sampled"
        first = 1 if self.sampled else 0  # the first flight is direct light, left out when sampled
        scene = self.scene
        survival = float(np.mean(np.clip(scene.albedo, 0.0, 1.0).max(axis=1))) if scene.triangle_count else 0.0
        per_photon = memory.segments_per_photon(survival, self.bounces)
        self.per_photon_kept = memory.segments_per_photon(survival, self.bounces, first)
        self.batch_size = memory.batch_photons(settings.batch_size, per_photon)
        self.threads = settings.threads or os.cpu_count() or 1
        if automatic:
            expect = settings.photons * per_photon / (RAYS_PER_SECOND * self.threads)
            self.report(Progress("prepare", 0.0, f"Photons: {si(settings.photons)}, chosen for the lightmaps' "
                                                 f"texels ({PHOTONS_PER_TEXEL} a texel; set them with --photons); "
                                                 f"tracing them should take about {expect:.2g} s on {self.threads} "
                                                 "threads"))
        self.need = memory.check(scene, settings, self.names, self.batch_size, per_photon, self.per_photon_kept)

    def check_cancel(self, fraction=None) -> None:
        if self.cancelled():
            raise BakeCancelled()

    def texels_and_tracer(self, reach_of) -> None:
        """The texels, their validity (walls and props standing on a texel's square), the sites the
        estimators run at, the widest disc, and the photon tracer."""
        scene, settings = self.scene, self.settings
        t0 = time.perf_counter()
        self.texels = texels = texels_mod.rasterise(scene)
        self.caster = RayCaster(scene.positions)
        t1 = time.perf_counter()
        texels.cuts = validity.find_cuts(texels, scene, self.caster, self.threads)
        self.validity_seconds = time.perf_counter() - t1
        every = any(estimators.get(name).every_texel for name in self.names)
        self.sites = sites_mod.choose(texels, 1 if every else indirect_spacing(settings, self.frame_state))
        self.at = self.sites.texels  # where the estimators run
        self.rasterise_seconds = time.perf_counter() - t0 - self.validity_seconds
        # DETP discs reach past a surface's edge by their radius and count what passes there: sun
        # photons must start that far beyond the footprint of the geometry too.
        self.discs = any(estimators.get(name).discs for name in self.names)
        self.radius = disc_radius(self.at, settings.estimator_settings) if self.discs else None
        self.reach = float(np.max(self.radius)) if self.discs and len(texels) else 0.0
        if self.discs and reach_of:
            self.reach = max(self.reach, _reach(scene, settings.estimator_settings, reach_of, settings.resolution))
        self.tracer = PhotonTracer(scene, settings.photons, self.bounces, settings.seed, self.batch_size,
                                   settings.threads, indirect_only=self.sampled, caster=self.caster, margin=self.reach)

    def direct_light(self) -> None:
        """Direct light by shadow rays (with direct='sampled'); the sharp lights' part apart when the
        lightmaps are denoised, as it stays as the shadow rays give it."""
        self.direct_e, self.sharp_e, self.direct_info = None, None, {"mode": self.settings.direct}
        self.direct_l1 = self.sharp_l1 = self.mask = None
        if not self.sampled:
            return
        settings, tracer = self.settings, self.tracer

        def direct_progress(fraction):
            self.check_cancel()
            self.report(Progress("direct", fraction, f"Direct light {100 * fraction:.0f} %"))
        if self.frame_state is not None:  # a frame of a range: re-sampled only where it can change
            self.direct_e, info = frame_direct.direct_irradiance(
                self.frame_state, self.scene, self.texels, self.caster, settings.direct_samples, settings.seed,
                tracer.threads, direct_progress, self.cancelled)
        else:
            self.sharp_e = np.zeros((len(self.texels), 3), np.float32) \
                if settings.denoise and denoise_mod.available() else None
            if settings.directional != "none":
                self.direct_l1 = np.zeros((len(self.texels), 9), np.float32)
                self.sharp_l1 = None if self.sharp_e is None else np.zeros((len(self.texels), 9), np.float32)
            if settings.shadowmask:
                self.mask = np.zeros((len(self.texels), 4), np.float32)
            self.direct_e, info = direct_mod.direct_irradiance(
                self.scene, self.texels, self.caster, settings.direct_samples, settings.seed, tracer.threads,
                direct_progress, self.cancelled, sharp=self.sharp_e, l1=self.direct_l1, sharp_l1=self.sharp_l1,
                shadowmask=settings.shadowmask, mask=self.mask, leave_out=settings.shadowmask_mode == "subtract")
        self.direct_info.update(info)

    def estimate_progress(self, fraction) -> None:
        self.check_cancel()
        self.report(Progress("estimate", fraction, f"Estimating {100 * fraction:.0f} %"))

    def estimators(self) -> None:
        """The discs' clearance, rise and extent (for the DETP family) and each estimator, built."""
        at, settings = self.at, self.settings
        self.expected_segments = int(self.tracer.photons * self.per_photon_kept)
        clearance = rise = extent = None
        t0 = time.perf_counter()
        if self.discs:
            self.report(Progress("prepare", 0.0, "Measuring disc clearance"))
            # A disc no wider than the piece of surface it lies on (a leaf card): rise.piece_extent.
            welds = welded_pieces(at, self.scene)
            extent = piece_extent(at, self.scene, welds)
            self.radius = radius = capped_radius(self.radius, extent)
            clearance = texels_mod.tangent_clearance(at, self.scene.positions, radius, 0.5 * SLAB * radius)
            rise = own_surface_rise(at, self.scene, radius, welds)
        self.clearance_seconds = time.perf_counter() - t0
        self.context = estimators.Context(scene_radius=self.tracer.escape_radius,
                                          expected_segments=self.expected_segments, clearance=clearance, rise=rise,
                                          extent=extent, frames=self.frame_state, scene=self.scene,
                                          directional=settings.directional != "none")
        self.runs, self.build = {}, {}
        for name in self.names:
            self.report(Progress("prepare", 0.5, f"Preparing {name}"))
            t1 = time.perf_counter()
            self.runs[name] = estimators.create(name, at, settings.estimator_settings, self.estimate_progress,
                                                self.context)
            self.build[name] = time.perf_counter() - t1
        self.spent = {name: 0.0 for name in self.names}
        # Noise from the spread between blocks of batches, for the estimators that stream.
        self.noise = {name: BatchNoise(len(at)) for name, est in self.runs.items() if est.streaming}

    def _partials(self, trace_progress):
        """The runs of batches traced here, or on a cluster's workers (distributed.py), in batch order."""
        runs_of_batches = blocks(self.tracer, self.runs, self.expected_segments)
        if self.cluster is None:
            settings = self.settings

            def over_time(batch_seconds):  # the next batch would take about as long as the last
                return bool(settings.time_limit) and \
                    time.perf_counter() - self.t_start + batch_seconds > settings.time_limit
            return (trace_batches(self.tracer, self.runs, block, self.cancelled, over_time)
                    for block in runs_of_batches)
        # A frame range's workers keep what they build themselves (the hybrid's static index), per frame:
        # what this process keeps between frames holds callables and would not travel.
        context = self.context if self.context.frames is None else \
            replace(self.context, frames=replace(self.context.frames, keep={}))
        job = TraceJob(self.scene, self.at, self.settings, self.names, self.bounces, self.batch_size, self.reach,
                       context)
        return self.cluster.partials(job, runs_of_batches, self.cancelled, trace_progress,
                                     worker_bytes(self.need, self.at, self.runs, runs_of_batches))

    def trace(self) -> None:
        """Trace batch by batch until the photons are spent or a stop (the user's, the time limit,
        the noise target) says enough; then the sums are the estimators'."""
        tracer, noise = self.tracer, self.noise
        primary, total = self.names[0], tracer.photons
        direct_at = None if self.direct_e is None else self.sites.of_sites(self.direct_e)
        self.stopped_by, self.current = "photons", {}
        totals = Totals(self.names)
        shown = [0]

        def trace_progress(photons):
            photons = shown[0] = max(shown[0], photons)  # units may finish out of order
            message = f"Tracing {si(photons)}/{si(total)} photons"
            if self.current:
                message += f" · noise {100 * max(self.current.values(), default=0.0):.2g} %"
            self.report(Progress("trace", photons / total, message))

        self.aside = contextlib.ExitStack()  # closed by _geometry_back
        self.aside.enter_context(self._aside_while_tracing())
        with contextlib.closing(iter(self._partials(trace_progress))) as partials:
            for part in partials:
                totals.add(part)
                share = tracer.schedule.share(totals.batches)
                for name in noise:
                    noise[name].update(totals.sums[name]["irradiance"], share)
                if primary in noise and noise[primary].groups >= 2:
                    self.current = noise[primary].relative(self.at.lightmaps,
                                                           partial(_luminance_so_far, direct_at, noise[primary], share))
                trace_progress(totals.stats.photons)
                self.check_cancel()
                self._show(totals, share)
                self.stopped_by = self._stop(part, totals)
                if self.stopped_by != "photons":
                    break
        tracer.stats, tracer.batches_done = totals.stats, totals.batches
        for name, est in self.runs.items():
            est.absorb(totals.sums.pop(name))  # the sums are the estimator's now: one copy, not two
            self.spent[name] += totals.seconds[name]

    def _aside_while_tracing(self):
        """The texels' positions and normals set aside while tracing when no estimator reads them
        then and the tracing is this process's own (48 bytes a texel: texels.geometry_set_aside)."""
        if self.cluster is None and self.frame_state is None and not any(
                estimators.get(name).texel_geometry_while_tracing for name in self.names):
            return texels_mod.geometry_set_aside(self.texels, self.scene)
        return contextlib.nullcontext()

    def _show(self, totals, share) -> None:
        """The live preview of the primary estimator's lightmaps so far, when one is asked."""
        if self.preview is None:
            return
        primary = self.names[0]
        so_far = partial(self.runs[primary].current, totals.sums[primary], self.check_cancel)
        self.preview(Snapshot(primary, totals.stats.photons, share, max(self.current.values(), default=None),
                              self.texels, partial(_snapshot_value, self.sites, so_far, self.direct_e, share),
                              self.runs[primary].slow_preview))

    def _stop(self, part, totals) -> str:
        """What stops the bake after this run of batches: "photons" (nothing yet), "user", the time
        limit or the noise target."""
        settings, noise, primary = self.settings, self.noise, self.names[0]
        more = totals.batches < self.tracer.batch_count
        if self.stop is not None and more and self.stop():
            return "user"
        if more and (part.stopped or (settings.time_limit and time.perf_counter() - self.t_start > settings.time_limit)):
            return "time_limit"
        if settings.target_noise and noise.get(primary) is not None and noise[primary].groups >= MIN_GROUPS \
                and max(self.current.values(), default=0.0) * 100 <= settings.target_noise:
            return "target_noise"
        return "photons"

    def results(self) -> dict:
        """Each estimator's lightmaps, denoised by region and with the fragments smoothed."""
        settings, texels, scene = self.settings, self.texels, self.scene
        self.estimate_progress(0.0)
        self.regions = None  # found once the texels' geometry is back (`_geometry_back`)
        # Texels of charts too narrow for OIDN take their neighbours' mean on the surface (fragments.py),
        # found lightmap by lightmap as each is denoised; a comparison's estimators share them (one
        # bake keeps none after its lightmap is done).
        self.fragments_of = None
        if settings.denoise:
            find = partial(fragments_mod.find, texels, scene=scene, caster=self.caster, threads=self.threads)
            if len(self.names) > 1:
                found = {}
                self.fragments_of = lambda lm: found[lm.name] if lm.name in found else found.setdefault(lm.name,
                                                                                                        find(lm))
            else:
                self.fragments_of = find
        results = {name: self._result(name) for name in self.names}
        if self.offset.any():
            texels.position += self.offset  # back where the texels are, in world space
        return results

    def _geometry_back(self) -> None:
        """The texels' positions and normals back where tracing set them aside (they stay aside
        until the first estimator's E/π is made: 48 bytes a texel less then), and the regions
        the denoiser keeps apart found: texels a wall separates (validity.regions), in lightmaps
        that have cuts, and the objects of an atlas (validity.by_object)."""
        self.aside.close()
        if self.regions is not None:
            return
        settings, texels, scene = self.settings, self.texels, self.scene
        t1 = time.perf_counter()
        self.regions = {lm.name: validity.regions(texels, lm, texels.cuts, self.caster, scene)
                        for lm in texels.lightmaps if settings.denoise and (texels.cuts.of[lm.texels] >= 0).any()}
        for lm in texels.lightmaps:
            if settings.denoise and len(lm.members) > 1:
                self.regions[lm.name] = validity.by_object(texels, lm, scene, self.regions.get(lm.name))
        self.validity_seconds += time.perf_counter() - t1

    def _result(self, name) -> BakeResult:
        settings, share = self.settings, self.tracer.share
        est = self.runs[name]
        t1 = time.perf_counter()
        out = est.finish()
        # The estimator's per-texel state goes before the images are made: the class still
        # answers what the rest of the loop asks (streaming, discs, stores_hits, fixed_noise).
        self.runs[name] = kind = type(est)
        est = None
        out.irradiance = self.sites.expand(out.irradiance)
        value = _value(out, self.direct_e, share)
        l1 = None if out.l1 is None else directional_mod.l1_value(self.sites.expand(out.l1), self.direct_l1, share)
        out.l1 = None
        self.spent[name] += time.perf_counter() - t1
        seconds = {"rasterise": self.rasterise_seconds, "validity": self.validity_seconds,
                   "direct": self.direct_info.get("seconds", 0.0), "clearance": self.clearance_seconds,
                   "build": self.build[name], "trace": self.tracer.stats.seconds, "estimate": self.spent[name]}
        # The noise sums go before the images are made (two float32s a texel).
        noise = self.noise.pop(name, None)
        if noise is not None:  # (relative noise, why there is none)
            measured = noise.relative(self.at.lightmaps, partial(_luminance, self.sites.of_sites(value), np.pi))
            noise = measured, "" if measured else noise.unmeasured(self.tracer.stats.photons)
        self._geometry_back()
        # An estimate with white noise is denoised apart from the direct light (denoise.py). The
        # last estimator of a plain bake hands the direct light over: nothing after it reads it.
        apart = self.direct_e is not None and kind.for_denoiser
        job = Finishing(replace(settings, estimator=name), self.texels, self.direct_e if apart else None,
                        self.sharp_e if apart else None, self.regions, self.fragments_of,
                        partial(texels_mod.geometry_set_aside, self.texels, self.scene))
        if name == self.names[-1] and l1 is None:
            self.direct_e = None
        made = job.images(value, out.counters)
        job = None
        if made.denoise_seconds is not None:
            seconds["denoise"] = made.denoise_seconds
        result = BakeResult(replace(settings, estimator=name), self.bounces, made.images, made.masks,
                            made.centre_masks, self.texels, value, self.tracer.stats, out.counters, seconds,
                            direct=dict(self.direct_info), warnings=made.warnings,
                            raw_images=RawImages(self.texels, value, settings.margin, made.images)
                            if made.denoise_seconds is not None else {})
        result.direct["denoised_apart"] = result.direct["sharp_kept"] = False
        if result.raw_images:
            result.direct["denoised_apart"], result.direct["sharp_kept"] = apart, apart and self.sharp_e is not None
        out = value = made = None
        if self.mask is not None:
            directional_mod.shadowmask_images(result, self.mask)
        if l1 is not None:
            t2 = time.perf_counter()
            sharp_part = None if self.sharp_l1 is None else (self.sharp_e, self.sharp_l1)
            directional_mod.make_images(result, l1, self.regions, self.fragments_of, sharp_part)
            result.seconds["directional"] = time.perf_counter() - t2
        result.stopped_by, result.share = self.stopped_by, share
        result.export = dict(getattr(self.scene, "export_stats", None) or {})
        result.cluster = dict(self.cluster.last) if self.cluster is not None else {}
        self._report_noise(kind, result, noise)
        return result

    def _report_noise(self, kind, result, noise) -> None:
        """The result's noise (`noise`: measured from its batches, (relative noise, why none), or
        None), warnings and memory figures."""
        settings, at = self.settings, self.at
        if noise is not None:
            result.noise, result.noise_unmeasured = noise
        elif kind.fixed_noise(settings.estimator_settings) is not None:
            fixed = kind.fixed_noise(settings.estimator_settings)
            result.noise = {lm.name: fixed for lm in self.texels.lightmaps}
            result.noise_unit = "per cent of each texel's own value (fixed by k)"
        else:
            result.noise_unmeasured = f"the {settings.estimator} estimator's noise is not read off its batches"
        result.warnings.extend(layout_warnings(at, settings.estimator_settings, self.radius if kind.discs else None))
        result.direct["indirect_spacing"] = self.sites.spacing
        result.direct["indirect_sites"] = len(at)
        k = settings.estimator_settings.k
        if kind.stores_hits and result.counters.get("hits", k) < k:
            result.warnings.append(f"setting 'k' = {k} is more than the {result.counters['hits']:,} photons the "
                                   "photon map stored: every texel averaged all of them (a blur over the scene); "
                                   "trace more photons or lower k")
        need = self.need
        result.memory = {"estimate_mb": round(need.total / 1e6, 1),
                         "parts_mb": {k: round(v / 1e6, 1) for k, v in need.parts.items()},
                         "peak_mb": round(memory.peak_bytes() / 1e6, 1), "batch_photons": self.batch_size}


OVERLAP_WARNING = 0.01  # a share of texels: Smart UV Project may fold a bent quad over a texel or two
OUTSIDE_WARNING = 0.001  # a share of UV area


def layout_warnings(texels, estimator_settings, radius=None) -> list:
    """What would make lightmaps silently wrong: overlapping lightmap UVs, UVs outside 0..1, and
    (`radius`: the DETP discs' radius per texel) discs wider than the objects they lie on."""
    out = []
    for lm in texels.lightmaps:
        if lm.overlap >= OVERLAP_WARNING:
            out.append(f"object '{lm.name}': {100 * lm.overlap:.0f} % of its lightmap texels lie under two or more "
                       "faces (overlapping lightmap UVs, e.g. Array or Mirror copies sharing them): those faces get "
                       "one shared value; give every face its own UV space (Lightmap Pack)")
        fragmented = charts_mod.warning(lm)
        if fragmented:
            out.append(fragmented)
        if lm.outside >= OUTSIDE_WARNING:
            out.append(f"object '{lm.name}': {100 * lm.outside:.1f} % of its lightmap UV area lies outside 0..1 and is "
                       "not baked: unwrap it into 0..1 (Lightmap Pack)")
    if radius is not None and len(texels):
        wide = []
        for lm in texels.lightmaps:
            pos = texels.position[lm.texels]
            across = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0)))
            r = float(np.min(radius[lm.texels]))
            if r >= across:
                wide.append(f"'{lm.name}' ({r:.3g} m against {across:.3g} m)")
        if wide:
            setting = ("radius", estimator_settings.radius) if estimator_settings.radius is not None else \
                ("radius_texels", estimator_settings.radius_texels)
            out.append(f"setting '{setting[0]}' = {setting[1]:g}: every disc is wider than the object it lies on "
                       f"for {', '.join(wide[:5])}{' …' if len(wide) > 5 else ''}, so each such lightmap is one "
                       f"blurred average: lower {setting[0]}")
    return out


def indirect_spacing(settings: BakeSettings, frame_state=None) -> int:
    """The sites' spacing (sites.py): the setting (0: chosen per lightmap by its size); always 1 in
    the paper's mode (the estimator then sees direct light, which is not smooth) and in frame ranges."""
    if settings.direct != "sampled" or frame_state is not None:
        return 1
    return int(settings.indirect_spacing)


def _luminance(per_texel, scale, start, stop) -> np.ndarray:
    """The mean over channels of rows start:stop of `per_texel` times `scale`, in float64."""
    lum = np.mean(per_texel[start:stop], axis=1, dtype=np.float64)
    lum *= scale
    return lum


def _luminance_so_far(direct_at, noise, share, start, stop) -> np.ndarray:
    """The luminance of the bake so far at sites start:stop: the direct light and the indirect
    sums scaled to the whole bake (`share` of it traced), for the noise shown while tracing."""
    lum = noise.previous[start:stop].astype(np.float64) / max(share, 1e-300)
    if direct_at is not None:
        lum += np.mean(direct_at[start:stop], axis=1, dtype=np.float64)
    return lum


def _snapshot_value(sites, current, direct_e, share) -> np.ndarray:
    irradiance = sites.expand(current() / share)
    return (irradiance if direct_e is None else irradiance + direct_e) / np.pi


def _value(est, direct_e, share) -> np.ndarray:
    """E/π per texel (Cycles' Diffuse bake unit, DIRECT+INDIRECT, no COLOR): summed in float64,
    kept as float32 (the images' precision); the estimate's own array is let go."""
    irradiance, est.irradiance = est.irradiance, None
    value = np.empty(irradiance.shape, np.float32)
    for a in range(0, len(irradiance), 1 << 18):  # a block at a time: no float64 copy of the whole bake
        b = a + (1 << 18)
        # stopped early (share < 1): the batches so far stand for the whole bake
        total = irradiance[a:b] / share if share < 1.0 else np.array(irradiance[a:b], np.float64)
        if direct_e is not None:
            total += direct_e[a:b]
        total /= np.pi
        value[a:b] = total
    return value


def bake(scene: Scene, settings: BakeSettings, out_dir: str | os.PathLike,
         progress: Optional[Callable[[Progress], None]] = None, cancel=None,
         export_seconds: float = 0.0, cluster=None) -> BakeResult:
    """Check the output folder first, then compute and write."""
    settings.validate()
    images.check_writable_dir(out_dir)
    result = compute(scene, settings, progress, cancel, cluster)
    result.seconds["export"] = export_seconds
    write(result, out_dir, progress, cancel)
    return result


