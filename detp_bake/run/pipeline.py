"""One bake, stage by stage (docs/architecture.md), over one object that holds what the whole bake
shares (its admitted settings, the centred scene, the photon budget, progress and cancel). Each
stage takes what it reads and returns what it made, so a stage's signature is its contract:

    lay_out(reach_of)                    -> Layout      texels, validity, sites, discs, the tracer
    plan_denoising(lay)                  -> Denoising   regions and fragments (finishing.plan)
    direct_light(lay)                    -> Direct      shadow rays (with direct='sampled')
    build_estimators(lay)                -> Estimation  the discs' clearance, each estimator
    trace(lay, light, est)               -> Traced      photon batches until a stop, sums handed over
    results(lay, plan, light, est, traced) -> {estimator: BakeResult}
    probes(lay, result)                  -> [ProbeGrid], report   light probes from the finished lightmaps

Everything that reads the texels' positions and normals runs before `trace` (or, for the disc
estimators, before their `finish`); from there to the end of `results` they are set aside (48
bytes a texel: texels.geometry_set_aside), once.

The settings were checked at the door (door.py) before the scene was exported; here they are taken
as they come, with the photon count chosen once.
"""
from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Optional

import numpy as np

from .. import estimators, options
from ..errors import BakeCancelled
from ..estimators.discs import SLAB, capped_radius, disc_radius
from ..estimators.rise import own_surface_rise, piece_extent, welded_pieces
from ..lightmap import denoise as denoise_mod, fragments as fragments_mod, sites as sites_mod, \
    texels as texels_mod, validity
from ..lightmap.noise import MIN_GROUPS, BatchNoise
from ..probes import baking as probes_mod, placement
from ..rays import RayCaster
from ..transport import direct as direct_mod, frame_direct, scattering
from ..transport.photons import PhotonTracer
from . import directional as directional_mod, door, memory
from .batches import Totals, TraceJob, blocks, trace_batches, worker_bytes
from .finishing import Denoising, Finishing, plan as plan_denoising
from .layout_warnings import layout_warnings
from .results import BakeResult, Progress, RawImages, Snapshot, cancel_fn, si
from .settings import BakeSettings

RAYS_PER_SECOND = 2.0e6  # photon segments traced a second and thread, for the time a bake announces
_NO_LEVEL = np.zeros((0, 3), np.float32)  # no direct light in the noise's luminance (noise.BatchNoise.relative)


@dataclass
class Layout:
    """Where the bake happens: the texels (with their validity cuts), the ray caster, the sites the
    estimators run at (`at`), the DETP discs' radius and reach (None and 0 without discs), the
    photon tracer, and the seconds rasterising and validity took."""
    texels: texels_mod.TexelSet
    caster: RayCaster
    sites: sites_mod.Sites
    at: texels_mod.TexelSet
    discs: bool
    radius: Optional[np.ndarray]
    reach: float
    tracer: PhotonTracer
    seconds: dict


@dataclass
class Direct:
    """Direct light per texel (E, W/m²) or None (the paper's mode); the sharp lights' part apart when
    lightmaps are denoised; L1 and the shadowmask when asked; `info` for report.json. The last
    estimator lets `e` go (results), nothing after it reads it."""
    e: Optional[np.ndarray] = None
    sharp: Optional[np.ndarray] = None
    l1: Optional[np.ndarray] = None
    sharp_l1: Optional[np.ndarray] = None
    mask: Optional[np.ndarray] = None
    info: dict = field(default_factory=dict)


@dataclass
class Estimation:
    """The estimators built (`runs`: by name; a class once its state has gone), what each spent
    building and estimating, the streaming ones' noise sums, their context, the discs' radius as
    capped to the surface they lie on, and the segments expected."""
    runs: dict
    build: dict
    spent: dict
    noise: dict
    context: estimators.Context
    radius: Optional[np.ndarray]
    expected_segments: int
    clearance_seconds: float
    layout_warnings: dict = field(default_factory=dict)


@dataclass
class Traced:
    """How tracing ended ("photons", "user", "time_limit", "target_noise"), the noise read last,
    and what tracing set aside (the texels' geometry: closed once the results are made)."""
    stopped_by: str
    current: dict
    aside: contextlib.ExitStack


class Pipeline:
    """What a bake shares across its stages (see the module's docstring for the stages)."""

    def __init__(self, scene, settings, names, progress, cancel, cluster, frame_state, stop, preview):
        memory.return_large_blocks()  # freed arrays go back to the system (glibc)
        memory.reset_peak()  # report.json's peak is this bake's
        admitted = door.with_photons(door.admitted(settings, names, frame_state=frame_state), scene)
        self.names = list(admitted.names)
        scene.check()
        # Probes are placed in world space, before the scene is centred: a bad grid is refused here.
        self.grids = placement.grids_for(scene, admitted.settings.probes, admitted.settings.probe_spacing)
        directional_mod.check_shadowmask(admitted.settings, scene, frame_state)
        self.settings = settings = wide(admitted.settings)
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
        self.survival = survival = scattering.survival(scene.albedo, scene.positions)
        per_photon = scattering.flights_per_photon(survival, self.bounces, certain=self.sampled)
        self.per_photon_kept = scattering.flights_per_photon(survival, self.bounces, first, certain=self.sampled)
        self.batch_size = memory.batch_photons(settings.batch_size, per_photon)
        self.threads = settings.threads or os.cpu_count() or 1
        if admitted.automatic:
            expect = settings.photons * per_photon / (RAYS_PER_SECOND * self.threads)
            per_texel = door.photons_per_texel(survival, settings)
            self.report(Progress("prepare", 0.0, f"Photons: {si(settings.photons)}, chosen for the lightmaps' "
                                                 f"texels ({per_texel:.3g} a texel; set them with --photons); "
                                                 f"tracing them should take about {expect:.2g} s on {self.threads} "
                                                 "threads"))
        self.need = memory.check(scene, settings, self.names, self.batch_size, per_photon, self.per_photon_kept,
                                 placement.cost(self.grids, len(settings.shadowmask))[1])

    def run(self, reach_of=None) -> dict:
        lay = self.lay_out(reach_of)
        plan = self.plan_denoising(lay)
        light = self.direct_light(lay)
        est = self.build_estimators(lay)
        traced = self.trace(lay, light, est)
        results = self.results(lay, plan, light, est, traced)
        if self.grids:
            primary = results[self.names[0]]
            primary.probes, primary.probe_info = self.probes(lay, primary)
        return results

    def check_cancel(self, fraction=None) -> None:
        if self.cancelled():
            raise BakeCancelled()

    def estimate_progress(self, fraction) -> None:
        self.check_cancel()
        self.report(Progress("estimate", fraction, f"Estimating {100 * fraction:.0f} %"))

    # Stages -------------------------------------------------------------------------------------
    def lay_out(self, reach_of) -> Layout:
        """The texels, their validity (walls and props standing on a texel's square), the sites the
        estimators run at, the widest disc (`reach_of`: objects whose discs count too, incremental.py),
        and the photon tracer."""
        scene, settings = self.scene, self.settings
        t0 = time.perf_counter()
        texels = texels_mod.rasterise(scene)
        caster = RayCaster(scene.positions)
        t1 = time.perf_counter()
        texels.cuts = validity.find_cuts(texels, scene, caster, self.threads)
        validity_seconds = time.perf_counter() - t1
        every = any(estimators.get(name).every_texel for name in self.names)
        sites = sites_mod.choose(texels, 1 if every else indirect_spacing(settings, self.frame_state))
        at = sites.texels
        seconds = {"rasterise": time.perf_counter() - t0 - validity_seconds, "validity": validity_seconds}
        # DETP discs reach past a surface's edge by their radius and count what passes there: sun
        # photons must start that far beyond the footprint of the geometry too.
        discs = any(estimators.get(name).discs for name in self.names)
        radius = disc_radius(at, settings.estimator_settings) if discs else None
        reach = float(np.max(radius)) if discs and len(texels) else 0.0
        if discs and reach_of:
            reach = max(reach, disc_reach_of(scene, settings.estimator_settings, reach_of, settings.resolution))
        tracer = PhotonTracer(scene, settings.photons, self.bounces, settings.seed, self.batch_size,
                              settings.threads, indirect_only=self.sampled, caster=caster, margin=reach,
                              segments=estimators.read_segments(self.names))
        return Layout(texels, caster, sites, at, discs, radius, reach, tracer, seconds)

    def plan_denoising(self, lay: Layout) -> Denoising:
        """The regions the denoiser keeps apart and the fragments it leaves to a mean over their
        neighbours (finishing.plan); nothing without denoising."""
        if not (self.settings.denoise and denoise_mod.available()):
            return Denoising()
        self.report(Progress("prepare", 0.0, "Finding the denoiser's regions and fragments"))
        # The photons' worth with the roulette at the first landing: what STARVED_PHOTONS counts.
        worth = self.settings.photons / door.roulette_share(self.survival, self.settings)
        plan = plan_denoising(lay.texels, self.scene, lay.caster, self.threads, int(worth))
        lay.seconds["validity"] += plan.seconds["regions"]
        lay.seconds["fragments"] = plan.seconds["fragments"]
        return plan

    def direct_light(self, lay: Layout) -> Direct:
        """Direct light by shadow rays (with direct='sampled'); the sharp lights' part apart when the
        lightmaps are denoised, as it stays as the shadow rays give it."""
        settings, n = self.settings, len(lay.texels)
        light = Direct(info={"mode": settings.direct})
        if not self.sampled:
            return light

        def direct_progress(fraction):
            self.check_cancel()
            self.report(Progress("direct", fraction, f"Direct light {100 * fraction:.0f} %"))
        if self.frame_state is not None:  # a frame of a range: re-sampled only where it can change
            light.e, info = frame_direct.direct_irradiance(
                self.frame_state, self.scene, lay.texels, lay.caster, settings.direct_samples, settings.seed,
                lay.tracer.threads, direct_progress, self.cancelled)
        else:
            light.sharp = np.zeros((n, 3), np.float32) if settings.denoise and denoise_mod.available() else None
            if settings.directional != "none":
                light.l1 = np.zeros((n, 9), np.float32)
                light.sharp_l1 = None if light.sharp is None else np.zeros((n, 9), np.float32)
            if settings.shadowmask:
                light.mask = np.zeros((n, 4), np.float32)
            light.e, info = direct_mod.direct_irradiance(
                self.scene, lay.texels, lay.caster, settings.direct_samples, settings.seed, lay.tracer.threads,
                direct_progress, self.cancelled, sharp=light.sharp, l1=light.l1, sharp_l1=light.sharp_l1,
                shadowmask=settings.shadowmask, mask=light.mask, leave_out=settings.shadowmask_mode == "subtract")
        light.info.update(info)
        return light

    def build_estimators(self, lay: Layout) -> Estimation:
        """The discs' clearance, rise and extent (for the DETP family) and each estimator, built."""
        at, settings = lay.at, self.settings
        expected = int(lay.tracer.photons * self.per_photon_kept)
        clearance = rise = extent = None
        radius = lay.radius
        t0 = time.perf_counter()
        if lay.discs:
            self.report(Progress("prepare", 0.0, "Measuring disc clearance"))
            # A disc no wider than the piece of surface it lies on (a leaf card): rise.piece_extent.
            welds = welded_pieces(at, self.scene)
            extent = piece_extent(at, self.scene, welds)
            radius = capped_radius(radius, extent)
            clearance = texels_mod.tangent_clearance(at, self.scene.positions, radius, 0.5 * SLAB * radius)
            rise = own_surface_rise(at, self.scene, radius, welds)
        clearance_seconds = time.perf_counter() - t0
        context = estimators.Context(scene_radius=lay.tracer.escape_radius, expected_segments=expected,
                                     clearance=clearance, rise=rise, extent=extent, frames=self.frame_state,
                                     scene=self.scene, directional=settings.directional != "none")
        runs, build = {}, {}
        for name in self.names:
            self.report(Progress("prepare", 0.5, f"Preparing {name}"))
            t1 = time.perf_counter()
            runs[name] = estimators.create(name, at, settings.estimator_settings, self.estimate_progress, context)
            build[name] = time.perf_counter() - t1
        # Noise from the spread between blocks of batches, for the estimators that stream.
        noise = {name: BatchNoise(len(at)) for name, est in runs.items() if est.streaming}
        warned = {name: layout_warnings(at, settings.estimator_settings, radius if run.discs else None)
                  for name, run in runs.items()}
        return Estimation(runs, build, {name: 0.0 for name in self.names}, noise, context, radius, expected,
                          clearance_seconds, warned)

    def trace(self, lay: Layout, light: Direct, est: Estimation) -> Traced:
        """Trace batch by batch until the photons are spent or a stop (the user's, the time limit,
        the noise target) says enough; then the sums are the estimators'."""
        tracer, noise = lay.tracer, est.noise
        primary, total = self.names[0], tracer.photons
        direct_at = _NO_LEVEL if light.e is None else lay.sites.of_sites(light.e)
        traced = Traced("photons", {}, contextlib.ExitStack())  # its aside is closed by `results`
        totals = Totals(self.names)
        shown = [0]

        def trace_progress(photons):
            photons = shown[0] = max(shown[0], photons)  # units may finish out of order
            message = f"Tracing {si(photons)}/{si(total)} photons"
            if traced.current:
                message += f" · noise {100 * max(traced.current.values(), default=0.0):.2g} %"
            self.report(Progress("trace", photons / total, message))

        if self._geometry_may_go(lay, while_tracing=True):
            traced.aside.enter_context(texels_mod.geometry_set_aside(lay.texels, self.scene))
        with contextlib.closing(iter(self._partials(lay, est, trace_progress))) as partials:
            for part in partials:
                totals.add(part)
                share = tracer.schedule.share(totals.batches)
                for name in noise:
                    noise[name].update(totals.sums[name]["irradiance"], share)
                if primary in noise and noise[primary].groups >= 2:
                    traced.current = noise[primary].relative(lay.at.lightmaps, direct_at, 1.0, 1.0 / max(share, 1e-300))
                trace_progress(totals.stats.photons)
                self.check_cancel()
                self._show(lay, light, est, traced, totals, share)
                traced.stopped_by = self._stop(lay, est, traced, part, totals)
                del part  # its sums are in the totals: an estimator may clear and fill them again
                if traced.stopped_by != "photons":
                    break
        tracer.stats, tracer.batches_done = totals.stats, totals.batches
        for name, run in est.runs.items():
            run.absorb(totals.sums.pop(name))  # the sums are the estimator's now: one copy, not two
            est.spent[name] += totals.seconds[name]
        return traced

    def results(self, lay: Layout, plan: Denoising, light: Direct, est: Estimation, traced: Traced) -> dict:
        """Each estimator's lightmaps, denoised by region and with the fragments smoothed; then the
        texels' geometry back where tracing set it aside."""
        self.estimate_progress(0.0)
        fragments_mod.set_passes(plan.fragments, traced.current)  # as many means as the noise asks
        with traced.aside:
            results = {name: self._result(name, lay, plan, light, est, traced) for name in self.names}
        if self.offset.any():
            lay.texels.position += self.offset  # back where the texels are, in world space
        return results

    def probes(self, lay: Layout, result: BakeResult) -> tuple[list, dict]:
        """The light probes (probes/), gathered from the primary estimator's finished lightmaps; the
        shadowmask lights' direct light apart, as in the lightmaps."""
        settings = self.settings

        def probe_progress(fraction):
            self.check_cancel()
            self.report(Progress("probes", fraction, f"Light probes {100 * fraction:.0f} %"))
        info = probes_mod.bake_probes(self.grids, self.scene, lay.caster, result.images, settings.probe_rays,
                                      settings.direct_samples, settings.seed, settings.shadowmask, self.offset,
                                      probe_progress, leave_out=settings.shadowmask_mode == "subtract")
        result.seconds["probes"] = info["seconds"]
        return self.grids, info

    # Tracing's helpers ----------------------------------------------------------------------------
    def _partials(self, lay: Layout, est: Estimation, trace_progress):
        """The runs of batches traced here, or on a cluster's workers (distributed.py), in batch order."""
        runs_of_batches = blocks(lay.tracer, est.runs, est.expected_segments)
        if self.cluster is None:
            settings = self.settings

            def over_time(batch_seconds):  # the next batch would take about as long as the last
                return bool(settings.time_limit) and \
                    time.perf_counter() - self.t_start + batch_seconds > settings.time_limit
            return (trace_batches(lay.tracer, est.runs, block, self.cancelled, over_time)
                    for block in runs_of_batches)
        # A frame range's workers keep what they build themselves (the hybrid's static index), per frame:
        # what this process keeps between frames holds callables and would not travel.
        context = est.context if est.context.frames is None else \
            replace(est.context, frames=replace(est.context.frames, keep={}))
        job = TraceJob(self.scene, lay.at, self.settings, self.names, self.bounces, self.batch_size, lay.reach,
                       context)
        return self.cluster.partials(job, runs_of_batches, self.cancelled, trace_progress,
                                     worker_bytes(self.need, lay.at, est.runs, runs_of_batches))

    def _geometry_may_go(self, lay: Layout, while_tracing: bool) -> bool:
        """Whether the texels' positions and normals may be set aside (48 bytes a texel:
        texels.geometry_set_aside) now, once: while tracing, only when the tracing is this process's
        own, not a frame of a range, and no estimator reads them then (the disc estimators do, until
        their `finish`)."""
        if lay.texels.position is None:
            return False
        return not while_tracing or (self.cluster is None and self.frame_state is None and not any(
            estimators.get(name).texel_geometry_while_tracing for name in self.names))

    def _show(self, lay: Layout, light: Direct, est: Estimation, traced: Traced, totals, share) -> None:
        """The live preview of the primary estimator's lightmaps so far, when one is asked."""
        if self.preview is None:
            return
        primary = self.names[0]
        so_far = partial(est.runs[primary].current, totals.sums[primary], self.check_cancel)
        self.preview(Snapshot(primary, totals.stats.photons, share, max(traced.current.values(), default=None),
                              lay.texels, partial(_snapshot_value, lay.sites, so_far, light.e, share),
                              est.runs[primary].slow_preview))

    def _stop(self, lay: Layout, est: Estimation, traced: Traced, part, totals) -> str:
        """What stops the bake after this run of batches: "photons" (nothing yet), "user", the time
        limit or the noise target."""
        settings, noise, primary = self.settings, est.noise, self.names[0]
        more = totals.batches < lay.tracer.batch_count
        if self.stop is not None and more and self.stop():
            return "user"
        if more and (part.stopped or (settings.time_limit and time.perf_counter() - self.t_start > settings.time_limit)):
            return "time_limit"
        if settings.target_noise and noise.get(primary) is not None and noise[primary].groups >= MIN_GROUPS \
                and max(traced.current.values(), default=0.0) * 100 <= settings.target_noise:
            return "target_noise"
        return "photons"

    # The results' helpers ---------------------------------------------------------------------------
    def _result(self, name, lay: Layout, plan: Denoising, light: Direct, est: Estimation,
                traced: Traced) -> BakeResult:
        share, sites = lay.tracer.share, lay.sites
        run = est.runs[name]
        t1 = time.perf_counter()
        out = run.finish()
        if name == self.names[-1] and self._geometry_may_go(lay, while_tracing=False):
            traced.aside.enter_context(texels_mod.geometry_set_aside(lay.texels, self.scene))  # the last read done
        # The estimator's per-texel state goes before the images are made: the class still
        # answers what the rest of the loop asks (streaming, discs, stores_hits, fixed_noise).
        est.runs[name] = kind = type(run)
        run = None
        out.irradiance = sites.expand(out.irradiance)
        value = _value(out, light.e, share)
        l1 = None if out.l1 is None else directional_mod.l1_value(sites.expand(out.l1), light.l1, share)
        out.l1 = None
        est.spent[name] += time.perf_counter() - t1
        seconds = {**lay.seconds, "direct": light.info.get("seconds", 0.0), "clearance": est.clearance_seconds,
                   "build": est.build[name], "trace": lay.tracer.stats.seconds, "estimate": est.spent[name]}
        # The noise sums go before the images are made (two float32s a texel).
        noise = est.noise.pop(name, None)
        if noise is not None:  # (relative noise, why there is none)
            measured = noise.relative(lay.at.lightmaps, sites.of_sites(value), np.pi)
            noise = measured, "" if measured else noise.unmeasured(lay.tracer.stats.photons)
        result = self._images(name, kind, lay, plan, light, value, out.counters, seconds, last=l1 is None)
        out = value = None
        if light.mask is not None:
            directional_mod.shadowmask_images(result, light.mask)
        if l1 is not None:
            t2 = time.perf_counter()
            sharp_part = None if light.sharp_l1 is None else (light.sharp, light.sharp_l1)
            directional_mod.make_images(result, l1, plan, sharp_part)
            result.seconds["directional"] = time.perf_counter() - t2
        result.stopped_by, result.share = traced.stopped_by, share
        result.export = dict(getattr(self.scene, "export_stats", None) or {})
        result.cluster = dict(self.cluster.last) if self.cluster is not None else {}
        self._report_noise(kind, result, noise, lay, est)
        return result

    def _images(self, name, kind, lay: Layout, plan: Denoising, light: Direct, value, counters, seconds,
                last) -> BakeResult:
        """Estimator `name`'s images (finishing.py) as a BakeResult. An estimate with white noise is
        denoised apart from the direct light (denoise.py); the last estimator of a plain bake (`last`:
        no L1 after it) hands the direct light over, as nothing after it reads it."""
        settings = replace(self.settings, estimator=name)
        apart = light.e is not None and kind.for_denoiser
        job = Finishing(settings, lay.texels, light.e if apart else None, light.sharp if apart else None, plan)
        if name == self.names[-1] and last:
            light.e = None
        made = job.images(value, counters)
        job = None
        if made.denoise_seconds is not None:
            seconds["denoise"] = made.denoise_seconds
        result = BakeResult(settings, self.bounces, made.images, made.masks, made.centre_masks, lay.texels, value,
                            lay.tracer.stats, counters, seconds, direct=dict(light.info), warnings=made.warnings,
                            raw_images=RawImages(lay.texels, value, settings.margin, made.images)
                            if made.denoise_seconds is not None else {})
        result.direct["denoised_apart"] = result.direct["sharp_kept"] = False
        if result.raw_images:
            result.direct["denoised_apart"], result.direct["sharp_kept"] = apart, apart and light.sharp is not None
        return result

    def _report_noise(self, kind, result, noise, lay: Layout, est: Estimation) -> None:
        """The result's noise (`noise`: measured from its batches, (relative noise, why none), or
        None), warnings and memory figures."""
        settings, at = self.settings, lay.at
        if noise is not None:
            result.noise, result.noise_unmeasured = noise
        elif kind.fixed_noise(settings.estimator_settings) is not None:
            fixed = kind.fixed_noise(settings.estimator_settings)
            result.noise = {lm.name: fixed for lm in lay.texels.lightmaps}
            result.noise_unit = "per cent of each texel's own value (fixed by k)"
        else:
            result.noise_unmeasured = f"the {result.settings.estimator} estimator's noise is not read off its batches"
        result.warnings.extend(est.layout_warnings[result.settings.estimator])
        result.direct["indirect_spacing"] = lay.sites.spacing
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


def wide(settings: BakeSettings) -> BakeSettings:
    """The settings with the disc radius in texels set from the direct-light mode when unset."""
    if settings.estimator_settings.radius_texels is not None:
        return settings
    texels_wide = options.RADIUS_TEXELS_INDIRECT if settings.direct == "sampled" else options.RADIUS_TEXELS_ALL
    return replace(settings, estimator_settings=replace(settings.estimator_settings, radius_texels=texels_wide))


def disc_reach_of(scene, estimator_settings, names, resolution: int) -> float:
    """The widest disc of objects `names` (a centred scene: the same floats as `rasterise` finds)."""
    if estimator_settings.radius is not None:
        return float(estimator_settings.radius)
    sizes = texels_mod.texel_sizes(scene, names, resolution)
    return max((float(np.float64(size) * float(estimator_settings.radius_texels)) for size in sizes.values()),
               default=0.0)


def indirect_spacing(settings: BakeSettings, frame_state=None) -> int:
    """The sites' spacing (sites.py): the setting (0: chosen per lightmap by its size); always 1 in
    the paper's mode (the estimator then sees direct light, which is not smooth) and in frame ranges."""
    if settings.direct != "sampled" or frame_state is not None:
        return 1
    return int(settings.indirect_spacing)


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
