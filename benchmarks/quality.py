"""Lightmap quality per second: Cycles' bake (raw and through OIDN) against ours, every method in one
run, against a converged Cycles reference on the same texels.

    python benchmarks/quality.py [--quick | --full] [--scenes cornell_box,l_room,window_room,patio,courtyard]
                                 [--sweep-scene l_room | none] [--compositor-check]
                                 [--references-only] [--out DIR] [--figures DIR]

Methods (each bakes every mesh of the scene at the configuration's resolution):
- `cycles`: Cycles' Diffuse bake (DIRECT+INDIRECT, no COLOR, adaptive sampling off), a ladder of
  sample counts (`blender.cycles_bake`, in this process);
- `cycles+oidn`: the same bakes, each lightmap then denoised by OIDN's RT filter in HDR mode
  (`denoise.denoise_lightmap(filter="RT")` on the texels Cycles baked: the gutter filled first,
  a white albedo guide): the library and filter Blender's compositor Denoise node runs. Its
  seconds are the bake's plus the denoiser's. `--compositor-check` denoises one bake through the
  Denoise node itself and prints how far the two outputs lie apart;
- `cycles+oidn-lm`: the same with OIDN's RTLightmap filter (no guide), the filter our bake uses;
- ours, a ladder of photon counts: `<estimator>` is the default pipeline (direct light by shadow
  rays, the estimator on indirect light, OIDN RTLightmap) with that estimator, `texel_histogram`
  being the default one; `<estimator>/no-denoise` the same bake's
  lightmaps before denoising, its seconds without the denoiser's (read off the same run);
  `<estimator>/photons` the paper's mode (the estimator sees every segment, no denoising).

Error: relative RMSE over the texels whose centre lies on the surface (`BakeResult.centre_masks`,
exactly the texels Cycles bakes), all objects and channels together, against the reference:
Cycles at the configuration's reference samples, baked as two halves with different seeds and
cached under OUT/cache (keyed by a hash of the .blend and the settings; `--references-only` bakes
them ahead). The halves' difference measures the reference's own noise σ_ref, which is taken out in
quadrature (`rmse`); the raw figure is kept as `rmse_measured`.

Runs are interleaved by cost (step i: Cycles at the i-th sample count, then each of ours at the
i-th photon count), so a slow spell on a shared machine hits all methods alike, and every run
records wall seconds, CPU seconds of all threads (Cycles', numba's, Embree's and OIDN's run in this
process) and the load average. A ladder stops once its error is below STOP (0.8 × 3 %: more runs
cannot change its times to the targets); Cycles' ladder once raw Cycles is at 5 % and Cycles + OIDN
below STOP. From each method's points: the time to reach 5 % and 3 %, interpolated on log-log
axes, and its ratio to Cycles + OIDN's, in wall and in CPU seconds ("≤": reached by the cheapest
run already, so an upper bound).

The sweeps (`--sweep-scene`) bake the default pipeline with `disc_index` at other disc radii
(`radius_texels`) and shadow-ray counts (`direct_samples`) and compare them at equal CPU seconds. Writes quality.json,
quality.md and one error/time plot per scene (plus one for the sweeps) under OUT, the plots also
under --figures when given.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import plots  # noqa: E402
import scenes  # noqa: E402  (puts the repository root on sys.path)

import numba  # noqa: E402
import numpy as np  # noqa: E402

from detp_bake.lightmap import denoise  # noqa: E402
from detp_bake.run.bake import BakeSettings, compute  # noqa: E402

TARGETS = (0.05, 0.03)
STOP = 0.8 * min(TARGETS)  # a ladder whose error is below this has its times to the targets
RIVAL = "cycles+oidn"
FULL_LADDERS = 2
CONFIGS = {
    "quick": dict(resolution=16, reference_spp=16, spp=[4, 8], photons=[10_000, 30_000],
                  estimators=["texel_histogram", "disc_index", "photon_map"], extra_photons=[10_000, 30_000],
                  old_mode=["disc_index"], old_mode_max=30_000, sweep_photons=[10_000, 30_000],
                  radius_texels=[1.5, 3.0], direct_samples=[4, 16], scene_resolution={},
                  scene_reference_spp={}, scene_spp={}),
    # sphere_cache finds exactly disc_index's crossings (same lightmaps, 5-7x the time): full only.
    "short": dict(resolution=64, reference_spp=2048, spp=[2, 4, 8, 16, 32, 64, 128, 256],
                  photons=[62_500, 125_000, 250_000, 500_000, 1_000_000, 2_000_000, 4_000_000, 8_000_000],
                  estimators=["texel_histogram", "disc_index", "photon_map"],
                  extra_photons=[250_000, 1_000_000, 4_000_000],
                  old_mode=["disc_index"], old_mode_max=4_000_000, sweep_photons=[250_000, 1_000_000, 4_000_000],
                  radius_texels=[1.0, 1.5, 2.0, 3.0, 4.0], direct_samples=[4, 8, 16, 32],
                  scene_resolution={}, scene_reference_spp={"window_room": 4096},
                  scene_spp={"window_room": [2, 4, 8, 16, 32, 64, 128, 256, 512]},
                  scene_photons={"window_room": [62_500, 125_000, 250_000, 500_000, 1_000_000, 2_000_000,
                                                 4_000_000, 8_000_000, 16_000_000]}),
    "full": dict(resolution=128, reference_spp=4096, spp=[2, 4, 8, 16, 32, 64, 128, 256, 512, 1024],
                 photons=[250_000, 500_000, 1_000_000, 2_000_000, 4_000_000, 8_000_000, 16_000_000],
                 estimators=["texel_histogram", "disc_index", "sphere_cache", "photon_map"],
                 extra_photons=[500_000, 2_000_000, 8_000_000], old_mode=["disc_index", "sphere_cache", "photon_map"],
                 old_mode_max=16_000_000, sweep_photons=[500_000, 2_000_000, 8_000_000],
                 radius_texels=[1.0, 1.5, 2.0, 3.0, 4.0, 6.0], direct_samples=[2, 4, 8, 16, 32, 64],
                 scene_resolution={}, scene_reference_spp={"window_room": 16384}, scene_spp={}),
}
SWEPT = "disc_index"  # the sweeps' estimator: the disc radius is its knob
PLOT_SKIP = {"cycles+oidn-lm", "photon_map/no-denoise", "sphere_cache/no-denoise"}  # in the tables only
LABELS = {
    "cycles": "Cycles bake, raw",
    "cycles+oidn": "Cycles bake + OIDN (RT, HDR)",
    "cycles+oidn-lm": "Cycles bake + OIDN (RTLightmap)",
}


def label(method: str) -> str:
    if method in LABELS:
        return LABELS[method]
    name, _, variant = method.partition("/")
    default = " (default)" if name == BakeSettings.estimator else ""
    return {"": f"`{name}`: shadow rays + estimator + OIDN{default}",
            "no-denoise": f"`{name}`: shadow rays + estimator, no denoise",
            "photons": f"`{name}`: photons only (paper's mode), raw"}[variant]


def timed(fn):
    """fn() with its wall seconds and process CPU seconds (all threads: Cycles', numba's, OIDN's)."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def cycles(bpy, blender, names, resolution, spp, seed):
    # Cycles' bake jitters its sample points uniformly over the texel, whatever the film's pixel
    # filter (measured: a 1-px box and the default 1.5-px Blackman-Harris bake the same bytes):
    # the same footprint as ours, the texel's covered square.
    with scenes.quiet_stdout():
        return blender.cycles_bake(bpy.context.scene, names, resolution=resolution, samples=spp, seed=seed)


def reference(bpy, blender, label_, names, resolution, spp, cache: Path, log):
    """Cycles at `spp` samples as two halves (seeds 1 and 2): (mean image per object, the halves)."""
    path = scenes.SAMPLES / f"{label_}.blend"
    key = hashlib.sha256(path.read_bytes() + json.dumps([resolution, spp, "halves", sorted(names)]).encode())
    file = cache / f"{label_}-{key.hexdigest()[:16]}.npz"
    seconds = None
    if file.exists():
        data = np.load(file)
        halves = [{n: data[f"{h}:{n}"] for n in names} for h in "ab"]
    else:
        log(f"{label_}: baking the reference, Cycles at {spp} spp ({resolution}² per object, once; cached)")
        halves, seconds, _ = timed(lambda: [cycles(bpy, blender, names, resolution, spp // 2, seed)
                                            for seed in (1, 2)])
        cache.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(file, **{f"{h}:{n}": img[n] for h, img in zip("ab", halves) for n in names})
    mean = {n: 0.5 * (halves[0][n] + halves[1][n]) for n in names}
    return mean, halves, seconds


def error(images, ref, masks, sigma_ref=0.0):
    """Relative RMSE (reference noise taken out in quadrature), the measured one, and mean bias."""
    a = np.concatenate([images[n][masks[n]] for n in masks]).astype(np.float64)
    b = np.concatenate([ref[n][masks[n]] for n in masks]).astype(np.float64)
    measured = float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(b))
    return {"rmse": float(np.sqrt(max(measured ** 2 - sigma_ref ** 2, 0.0))), "rmse_measured": measured,
            "bias": float(a.mean() / b.mean() - 1)}


def reference_noise(halves, masks):
    """Relative noise of the mean of two independent halves: RMS of (a − b)/2 over the mean."""
    a = np.concatenate([halves[0][n][masks[n]] for n in masks]).astype(np.float64)
    b = np.concatenate([halves[1][n][masks[n]] for n in masks]).astype(np.float64)
    return float(np.sqrt(np.mean((a - b) ** 2)) / 2 / np.mean(0.5 * (a + b)))


def time_to(points, target):
    """Seconds to reach `target` RMSE, interpolated on log-log axes between the first pair of
    consecutive runs that straddles it; None if no run reaches it. `points` are (seconds, rmse) in
    order of cost (sample or photon count), not of seconds: on a shared machine a cheaper run now
    and then takes longer than the next one."""
    pts = list(points)
    if pts and pts[0][1] <= target:
        return float(pts[0][0])
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 > target >= e1:
            f = np.log(e0 / target) / np.log(e0 / e1)
            return float(np.exp(np.log(t0) + f * (np.log(t1) - np.log(t0))))
    return None


def error_at(points, seconds):
    """RMSE at `seconds`, interpolated on log-log axes between consecutive runs (in order of cost)
    whose times bracket it; None outside the measured range."""
    pts = list(points)
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if min(t0, t1) <= seconds <= max(t0, t1) and t0 != t1:
            f = np.log(seconds / t0) / np.log(t1 / t0)
            return float(np.exp(np.log(e0) + f * (np.log(e1) - np.log(e0))))
    return None


def summarise(res):
    """Times to the targets per method (wall and CPU seconds) and which of them are upper bounds,
    from the rows (recorded in order of cost)."""
    reach, reach_cpu, below = {}, {}, {}
    for method in dict.fromkeys(r["method"] for r in res["rows"]):
        mine = [r for r in res["rows"] if r["method"] == method]
        pts = [(r["seconds"], r["rmse"]) for r in mine]
        reach[method] = {f"{round(100 * t)}%": time_to(pts, t) for t in TARGETS}
        if all(r["cpu_seconds"] is not None for r in mine):
            cpu = [(r["cpu_seconds"], r["rmse"]) for r in mine]
            reach_cpu[method] = {f"{round(100 * t)}%": time_to(cpu, t) for t in TARGETS}
        # Reached at the cheapest run already: the time is only an upper bound.
        below[method] = [f"{round(100 * t)}%" for t in TARGETS if pts[0][1] <= t]
    res.update(reach=reach, reach_cpu=reach_cpu, upper_bounds=below)
    return res


def summarise_sweep(sw):
    """Each knob's values compared at equal CPU seconds (all threads; steadier than wall seconds
    when other jobs share the machine): RMSE at a common time inside every curve's range (the
    geometric middle of their overlap) and CPU seconds to the targets."""
    summary = {}
    for knob in ("radius_texels", "direct_samples"):
        curves = {}
        for r in sw["rows"]:
            if r["knob"] == knob and r["denoised"]:
                curves.setdefault(r["value"], []).append((r["cpu_seconds"], r["rmse"]))
        if not curves:
            continue
        lo = max(min(t for t, _ in p) for p in curves.values())
        hi = min(max(t for t, _ in p) for p in curves.values())
        at = float(np.sqrt(lo * hi)) if hi >= lo else None
        per = {str(v): {"error_at": None if at is None else error_at(p, at),
                        **{f"{round(100 * t)}%": time_to(p, t) for t in TARGETS}} for v, p in curves.items()}
        scored = [(e["error_at"], v) for v, e in per.items() if e["error_at"] is not None]
        summary[knob] = {"at_seconds": at, "values": per, "best": min(scored)[1] if scored else None}
    sw["summary"] = summary
    return sw


def denoise_all(images, masks, filter_):
    return {n: denoise.denoise_lightmap(images[n], masks[n], filter=filter_, margin=0) for n in masks}


def for_scene(cfg, label_):
    """The configuration with this scene's resolution (`res`), reference samples (`ref_spp`),
    Cycles ladder (`spp`) and photon ladder (`photons`)."""
    return dict(cfg, res=cfg["scene_resolution"].get(label_, cfg["resolution"]),
                ref_spp=cfg["scene_reference_spp"].get(label_, cfg["reference_spp"]),
                spp=cfg["scene_spp"].get(label_, cfg["spp"]),
                photons=cfg.get("scene_photons", {}).get(label_, cfg["photons"]))


def ours_settings(cfg, name, **kw):
    return BakeSettings(estimator=name, resolution=cfg["res"], **kw)


def bench_scene(label_, cfg, cache, log):
    cfg = for_scene(cfg, label_)
    res = cfg["res"]
    scene = scenes.blend_scene(label_, res)
    import bpy
    from detp_bake import blender
    names = [o.name for o in scene.objects]
    ref, halves, ref_seconds = reference(bpy, blender, label_, names, res, cfg["ref_spp"], cache, log)

    # Load every compiled kernel and OIDN outside the timings; take the masks from this bake.
    warm = {}
    for name in dict.fromkeys(cfg["estimators"] + cfg["old_mode"]):
        warm = compute(scene, ours_settings(cfg, name, photons=2000))
        compute(scene, ours_settings(cfg, name, photons=2000, direct="photons", denoise=False))
    masks = warm.centre_masks
    cycles(bpy, blender, names, res, 1, 0)
    sigma = reference_noise(halves, masks)
    log(f"{label_}: {len(names)} objects, {scene.triangle_count:,} triangles, {res}² per object, "
        f"{sum(int(m.sum()) for m in masks.values()):,} texels compared; reference {cfg['ref_spp']} spp, "
        f"its own noise {100 * sigma:.2f} % (taken out of every RMSE in quadrature)")

    rows = []

    def record(method, cost, wall, cpu, images, phases=None):
        row = {"method": method, **cost, "seconds": wall, "cpu_seconds": cpu, "load": os.getloadavg()[0],
               **error(images, ref, masks, sigma)}
        if phases:
            row["phases"] = {k: round(v, 4) for k, v in phases.items()}
        rows.append(row)
        what = f"{cost['samples']:>9,} spp" if "samples" in cost else f"{cost['photons']:>9,} ph."
        cpu_text = "" if cpu is None else f" (CPU {cpu:7.2f} s)"
        log(f"{label_:12} {method:22} {what} {wall:8.2f} s{cpu_text}  RMSE {100 * row['rmse']:5.2f} % "
            f"(measured {100 * row['rmse_measured']:5.2f} %)  bias {100 * row['bias']:+5.2f} %")
        return row["rmse"]

    def run_cycles(spp):
        imgs, wall, cpu = timed(lambda: cycles(bpy, blender, names, res, spp, 7))
        raw = record("cycles", {"samples": spp}, wall, cpu, imgs)
        out = {}
        for method, filter_ in ((RIVAL, "RT"), ("cycles+oidn-lm", "RTLightmap")):
            den, w, c = timed(lambda: denoise_all(imgs, masks, filter_))
            out[method] = record(method, {"samples": spp}, wall + w, cpu + c, den)
        # Done once raw Cycles is at the upper target and Cycles + OIDN below the lower one.
        return raw <= max(TARGETS) and out[RIVAL] <= STOP

    def run_ours(name, photons, old_mode):
        if old_mode:
            r, wall, cpu = timed(lambda: compute(scene, ours_settings(cfg, name, photons=photons, direct="photons",
                                                                     denoise=False)))
            return record(f"{name}/photons", {"photons": photons}, wall, cpu, r.images, r.seconds) <= STOP
        r, wall, cpu = timed(lambda: compute(scene, ours_settings(cfg, name, photons=photons)))
        done = record(name, {"photons": photons}, wall, cpu, r.images, r.seconds) <= STOP
        d = r.seconds.get("denoise", 0.0)  # the same bake without its last step
        record(f"{name}/no-denoise", {"photons": photons}, wall - d, None, r.raw_images or r.images)
        return done

    # Ladders, interleaved by cost: step i runs Cycles at the i-th sample count and each of ours at
    # the i-th photon count. A ladder stops once more runs cannot change its times to the targets
    # (below STOP); the first FULL_LADDERS estimators climb the whole photon ladder (the default and
    # the best DETP estimator), the others fixed counts.
    ladders = [("cycles", list(cfg["spp"]), run_cycles)]
    for k, name in enumerate(cfg["estimators"]):
        counts = cfg["photons"] if k < FULL_LADDERS else [p for p in cfg["photons"] if p in cfg["extra_photons"]]
        ladders.append((name, counts, lambda p, n=name: run_ours(n, p, False)))
    for name in cfg["old_mode"]:
        counts = [p for p in cfg["photons"] if p <= cfg["old_mode_max"]]
        ladders.append((f"{name}/photons", counts, lambda p, n=name: run_ours(n, p, True)))
    stopped = set()
    for i in range(max(len(cfg["spp"]), len(cfg["photons"]))):
        for key, steps, run in ladders:
            index = i if key == "cycles" else (cfg["photons"][i] if i < len(cfg["photons"]) else None)
            if key in stopped or (key == "cycles" and i >= len(steps)) or (key != "cycles" and index not in steps):
                continue
            if run(steps[i] if key == "cycles" else index):
                stopped.add(key)

    return summarise({"scene": label_, "resolution": res, "objects": len(names), "triangles": scene.triangle_count,
                      "texels": sum(int(m.sum()) for m in masks.values()), "reference_spp": cfg["ref_spp"],
                      "reference_seconds": ref_seconds, "reference_noise": sigma, "rows": rows})


def sweep_scene(label_, cfg, cache, log):
    """`disc_index` in the default pipeline on one scene with other disc radii and shadow-ray counts,
    interleaved."""
    cfg = for_scene(cfg, label_)
    res = cfg["res"]
    scene = scenes.blend_scene(label_, res)
    import bpy
    from detp_bake import blender
    names = [o.name for o in scene.objects]
    ref, halves, _ = reference(bpy, blender, label_, names, res, cfg["ref_spp"], cache, log)
    base = BakeSettings(estimator=SWEPT)
    if base.estimator_settings.radius_texels is None:  # the bake picks the radius by direct mode
        from detp_bake import options
        wide = getattr(options, "RADIUS_TEXELS_INDIRECT" if base.direct == "sampled" else "RADIUS_TEXELS_ALL")
        base = replace(base, estimator_settings=replace(base.estimator_settings, radius_texels=wide))
    warm = compute(scene, ours_settings(cfg, base.estimator, photons=2000))
    masks = warm.centre_masks
    sigma = reference_noise(halves, masks)
    variants = [("radius_texels", v) for v in cfg["radius_texels"]] + \
               [("direct_samples", v) for v in cfg["direct_samples"]]
    rows = []
    for photons in cfg["sweep_photons"]:
        done = {}  # the default settings belong to both sweeps: bake them once per photon count
        for knob, value in variants:
            radius = value if knob == "radius_texels" else base.estimator_settings.radius_texels
            samples = value if knob == "direct_samples" else base.direct_samples
            if (radius, samples) not in done:
                s = ours_settings(cfg, base.estimator, photons=photons, direct_samples=samples,
                                  estimator_settings=replace(base.estimator_settings, radius_texels=radius))
                done[radius, samples] = timed(lambda: compute(scene, s))
            r, wall, cpu = done[radius, samples]
            d = r.seconds.get("denoise", 0.0)
            for denoised, images, seconds, cpu_s in ((True, r.images, wall, cpu),
                                                     (False, r.raw_images or r.images, wall - d, None)):
                rows.append({"knob": knob, "value": value, "denoised": denoised, "photons": photons,
                             "seconds": seconds, "cpu_seconds": cpu_s, "direct_seconds": r.seconds.get("direct", 0.0),
                             "estimate_seconds": r.seconds.get("estimate", 0.0), "load": os.getloadavg()[0],
                             **error(images, ref, masks, sigma)})
            row = rows[-2]
            log(f"sweep {label_:10} {knob:15} {value:>5} {photons:>9,} ph. {wall:7.2f} s (CPU {cpu:7.2f} s)  "
                f"RMSE {100 * row['rmse']:5.2f} % (raw {100 * rows[-1]['rmse']:5.2f} %)  bias {100 * row['bias']:+5.2f} %")
    return summarise_sweep({"scene": label_, "resolution": res, "reference_spp": cfg["ref_spp"],
                            "reference_noise": sigma, "default": {"radius_texels": base.estimator_settings.radius_texels,
                                                                  "direct_samples": base.direct_samples},
                            "rows": rows})


def compositor_check(label_, cfg, log):
    """One Cycles bake of one object denoised twice, by `denoise_lightmap(filter="RT")` and by
    Blender's compositor Denoise node fed the same gutter-filled image and a white albedo image:
    the largest difference over the baked texels, relative to their mean."""
    import bpy
    from detp_bake import blender
    res = for_scene(cfg, label_)["res"]
    scene_ = scenes.blend_scene(label_, res)
    obj = scene_.objects[0].name
    masks = compute(scene_, BakeSettings(photons=1000, resolution=res, denoise=False)).centre_masks
    img = cycles(bpy, blender, [obj], res, cfg["spp"][0], 7)[obj]
    mask = masks[obj]
    ours = denoise.denoise_lightmap(img, mask, filter="RT", margin=0)
    filled = denoise.fill_gutter(np.maximum(np.where(mask[..., None], img, 0.0), 0.0).astype(np.float32), mask)
    try:
        node = _denoise_node(bpy, filled, np.ones_like(filled))
    except Exception as exc:  # noqa: BLE001  (a check, reported and skipped)
        log(f"compositor check skipped: {type(exc).__name__}: {exc}")
        return {"skipped": str(exc)}
    node = np.maximum(node, 0.0)
    scale = ours[mask].mean(axis=0) / np.maximum(node[mask].mean(axis=0), 1e-30)  # ours keeps the raw mean
    diff = np.abs(node[mask] * scale - ours[mask]).max() / ours[mask].mean()
    out = {"scene": label_, "object": obj, "samples": cfg["spp"][0], "blender": bpy.app.version_string,
           "max_relative_difference": float(diff)}
    log(f"compositor check ({label_}/{obj}, {cfg['spp'][0]} spp, Blender {bpy.app.version_string}): Denoise node "
        f"and denoise_lightmap(RT) differ by at most {100 * diff:.3g} % of the mean over baked texels")
    return out


def _denoise_node(bpy, color, albedo):
    """Render a scene with no objects whose compositor runs Image (+ Albedo image) → Denoise (HDR,
    no prefilter, high quality) → output; returns the (H, W, 3) result, row 0 at the bottom."""
    import OpenImageIO as oiio
    h, w, _ = color.shape
    scene = bpy.data.scenes.new("detp_bake denoise check")
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = w, h, 100
    scene.view_settings.view_transform = "Standard"

    def image(name, a):
        img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
        img.colorspace_settings.name = "Non-Color"
        img.pixels.foreach_set(np.concatenate([a, np.ones((h, w, 1), np.float32)], -1).ravel())
        return img

    if hasattr(scene, "compositing_node_group"):  # Blender 5
        tree = bpy.data.node_groups.new("detp_bake denoise check", "CompositorNodeTree")
        scene.compositing_node_group = tree
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        out = tree.nodes.new("NodeGroupOutput").inputs[0]
    else:
        scene.use_nodes = True
        tree = scene.node_tree
        for n in list(tree.nodes):
            tree.nodes.remove(n)
        out = tree.nodes.new("CompositorNodeComposite").inputs["Image"]
    col = tree.nodes.new("CompositorNodeImage")
    col.image = image("detp_bake check color", color)
    alb = tree.nodes.new("CompositorNodeImage")
    alb.image = image("detp_bake check albedo", albedo)
    den = tree.nodes.new("CompositorNodeDenoise")
    for key, value in (("use_hdr", True), ("prefilter", "NONE"), ("quality", "HIGH")):
        if hasattr(den, key):
            setattr(den, key, value)
    for key, value in (("HDR", True), ("Prefilter", "None"), ("Quality", "High")):
        if key in den.inputs:
            try:
                den.inputs[key].default_value = value
            except (TypeError, ValueError):
                pass
    tree.links.new(col.outputs["Image"], den.inputs["Image"])
    tree.links.new(alb.outputs["Image"], den.inputs["Albedo"])
    tree.links.new(den.outputs["Image"], out)
    path = Path(tempfile.mkdtemp(prefix="detp_bake_check_")) / "denoised.exr"
    scene.render.filepath = str(path)
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    with scenes.quiet_stdout():
        bpy.ops.render.render(scene=scene.name, write_still=True)
    return np.ascontiguousarray(oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)[::-1, :, :3])


def ratio_table(res):
    """Markdown: time to 5 % and 3 % per method and its ratio to Cycles + OIDN's, in wall seconds and
    (a check on a shared machine) in CPU seconds of all threads."""
    bounds = res.get("upper_bounds", {})
    lines = ["| method | time to 5 % | ratio | CPU ratio | time to 3 % | ratio | CPU ratio |",
             "|---|---:|---:|---:|---:|---:|---:|"]

    def ratio(table, method, key):
        s, r = table.get(method, {}).get(key), table.get(RIVAL, {}).get(key)
        if s is None or r is None:
            return "—"
        mine, theirs = key in bounds.get(method, []), key in bounds.get(RIVAL, [])
        # An upper bound on ours over an exact rival time bounds the ratio from above, and so on.
        mark = "≤ " if mine and not theirs else "≥ " if theirs and not mine else "~ " if mine else ""
        return f"{mark}{s / r:.2f}"

    for method, t in res["reach"].items():
        cells = []
        for key in ("5%", "3%"):
            s = t[key]
            cells.append("not reached" if s is None else f"{'≤ ' if key in bounds.get(method, []) else ''}{s:.1f} s")
            cells.append(ratio(res["reach"], method, key))
            cells.append(ratio(res.get("reach_cpu", {}), method, key))
        lines.append(f"| {label(method)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def markdown(results, sweeps, cores, threads):
    out = []
    for res in results:
        out.append(f"### {res['scene']} ({res['objects']} objects, {res['triangles']:,} triangles, "
                   f"{res['resolution']}² per object; reference {res['reference_spp']} spp, its noise "
                   f"{100 * res['reference_noise']:.2f} % taken out; {cores} cores, {threads} threads)\n")
        out.append(ratio_table(res))
        costs = {}
        for r in res["rows"]:
            costs.setdefault(r["method"], []).append(r)
        out.append("\n| method | runs: RMSE (seconds) |\n|---|---|")
        for method, rs in costs.items():
            cells = ", ".join(f"{100 * r['rmse']:.1f} % ({r['seconds']:.1f} s)" for r in rs)
            out.append(f"| {label(method)} | {cells} |")
        out.append("")
    for sw in sweeps:
        out.append(f"### Sweeps on {sw['scene']} ({sw['resolution']}², {SWEPT} in the default pipeline; "
                   "at equal CPU seconds)\n")
        for knob, s in sw["summary"].items():
            at = s["at_seconds"]
            out.append(f"`{knob}` (others at their defaults); RMSE at {at:.1f} CPU s, best: **{s['best']}**\n"
                       if at else f"`{knob}`: no common time range\n")
            out.append("| value | RMSE at equal CPU time | CPU s to 5 % | CPU s to 3 % |\n|---:|---:|---:|---:|")
            for value, e in s["values"].items():
                fmt = lambda x: "not reached" if x is None else f"{x:.1f} s"  # noqa: E731
                err = "—" if e["error_at"] is None else f"{100 * e['error_at']:.2f} %"
                out.append(f"| {value} | {err} | {fmt(e['5%'])} | {fmt(e['3%'])} |")
            out.append("")
    return "\n".join(out)


def plot(res, out_dirs):
    plt = plots.pyplot()
    if plt is None:
        return None
    fig, ax = plt.subplots(figsize=(7, 5))
    for method in dict.fromkeys(r["method"] for r in res["rows"]):
        if method in PLOT_SKIP:
            continue
        pts = [(r["seconds"], r["rmse"]) for r in res["rows"] if r["method"] == method]  # in order of cost
        style = "s--" if method.startswith("cycles") else "o-"
        ax.loglog(*zip(*pts), style, label=label(method).replace("`", ""), ms=4)
    for level in TARGETS:
        ax.axhline(level, color="grey", lw=0.6, ls=":")
    ax.set(xlabel="wall seconds", ylabel="relative RMSE vs converged Cycles",
           title=f"{res['scene']} ({res['resolution']}² per object)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    paths = []
    for d in out_dirs:
        path = Path(d) / f"quality_{res['scene']}.png"
        fig.savefig(path, dpi=90)
        paths.append(str(path))
    plt.close(fig)
    return paths[0]


def plot_sweep(sw, out_dirs):
    plt = plots.pyplot()
    if plt is None:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, knob in zip(axes, ("radius_texels", "direct_samples")):
        values = dict.fromkeys(r["value"] for r in sw["rows"] if r["knob"] == knob)
        for value in values:
            pts = [(r["cpu_seconds"], r["rmse"]) for r in sw["rows"]
                   if r["knob"] == knob and r["value"] == value and r["denoised"]]
            ax.loglog(*zip(*pts), "o-", label=f"{knob} {value}", ms=4)
        ax.set(xlabel="CPU seconds (all threads)", ylabel="relative RMSE vs converged Cycles",
               title=f"{sw['scene']}: {knob}")
        ax.legend(fontsize=6)
    fig.tight_layout()
    paths = []
    for d in out_dirs:
        path = Path(d) / f"quality_sweeps_{sw['scene']}.png"
        fig.savefig(path, dpi=90)
        paths.append(str(path))
    plt.close(fig)
    return paths[0]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_true", help="seconds: checks that the script works")
    group.add_argument("--full", action="store_true", help="the full sweeps (hours on 2 cores)")
    ap.add_argument("--scenes", default="cornell_box,l_room,window_room,patio,courtyard", help="comma-separated, or none")
    ap.add_argument("--sweep-scene", default="l_room", help="scene for the radius/shadow-ray sweeps, or none")
    ap.add_argument("--estimators", default=None, help="comma-separated subset of the configuration's estimators")
    ap.add_argument("--replot", metavar="JSON", default=None,
                    help="no baking: re-derive the tables and plots from an earlier quality.json")
    ap.add_argument("--references-only", action="store_true",
                    help="bake (and cache) the references of --scenes, then stop")
    ap.add_argument("--compositor-check", action="store_true",
                    help="also denoise one Cycles bake through Blender's compositor Denoise node")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    ap.add_argument("--figures", default=None, help="also save the plots here (e.g. benchmarks/figures)")
    args = ap.parse_args(argv)
    cfg = dict(CONFIGS["quick" if args.quick else "full" if args.full else "short"])
    if args.estimators:
        cfg["estimators"] = args.estimators.split(",")
        cfg["old_mode"] = [e for e in cfg["old_mode"] if e in cfg["estimators"]]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    dirs = [out] + ([Path(args.figures)] if args.figures else [])
    for d in dirs:
        d.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()

    def log(msg):
        print(f"[{time.perf_counter() - t_start:7.1f} s] {msg}", flush=True)

    log(f"{os.cpu_count()} cores, {numba.get_num_threads()} threads; OIDN through pyoidn "
        "(Intel Open Image Denoise, the library behind Blender's compositor Denoise node)")
    if args.replot:
        doc = json.loads(Path(args.replot).read_text())
        for res in doc["results"]:
            res["plot"] = plot(summarise(res), dirs)
        for sw in doc["sweeps"]:
            sw["plot"] = plot_sweep(summarise_sweep(sw), dirs)
        text = markdown(doc["results"], doc["sweeps"], doc["cores"], doc["threads"])
        print(text)
        (out / "quality.json").write_text(json.dumps(doc, indent=1, allow_nan=False))
        (out / "quality.md").write_text(text + "\n")
        return 0
    if args.references_only:
        import bpy
        from detp_bake import blender
        for label_ in args.scenes.split(","):
            c = for_scene(cfg, label_)
            names = [o.name for o in scenes.blend_scene(label_, c["res"]).objects]
            _, _, seconds = reference(bpy, blender, label_, names, c["res"], c["ref_spp"], out / "cache", log)
            log(f"{label_}: reference " + ("cached already" if seconds is None else f"baked in {seconds:.0f} s"))
        return 0
    first = args.sweep_scene if args.scenes == "none" else args.scenes.split(",")[0]
    check = compositor_check(first, cfg, log) if args.compositor_check else None
    results, sweeps = [], []
    for label_ in [] if args.scenes == "none" else args.scenes.split(","):
        res = bench_scene(label_, cfg, out / "cache", log)
        res["plot"] = plot(res, dirs)
        results.append(res)
        print(ratio_table(res), "\n", flush=True)
    if args.sweep_scene != "none":
        sw = sweep_scene(args.sweep_scene, cfg, out / "cache", log)
        sw["plot"] = plot_sweep(sw, dirs)
        sweeps.append(sw)
    text = markdown(results, sweeps, os.cpu_count(), numba.get_num_threads())
    print(text, flush=True)
    doc = {"cores": os.cpu_count(), "threads": numba.get_num_threads(), "config": cfg,
           "seconds": time.perf_counter() - t_start, "compositor_check": check, "results": results, "sweeps": sweeps}
    (out / "quality.json").write_text(json.dumps(doc, indent=1, allow_nan=False))
    (out / "quality.md").write_text(text + "\n")
    log(f"wrote {out / 'quality.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
