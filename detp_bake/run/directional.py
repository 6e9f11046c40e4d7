"""Directional lightmaps (`--directional sh|dominant`, lightmap/sh.py) from a bake's per-texel L1:
the settings checked before any work, and the images made beside the plain lightmaps.

L1 is signed, which OIDN does not take, but L0 + L1ₐ (each axis a) is not negative wherever
|L1| ≤ L0 holds (after the clamp), so each axis is denoised as L0 + L1ₐ less the denoised L0, by
the same call, chart masks, regions and fragments as the plain lightmap. The sharp lights' part
(point, spot, sun by shadow rays) is kept as the rays give it, as in the plain lightmap. The clamp
then holds the result to |L1| ≤ the plain lightmap's L0 (the number of texels it changed goes to
report.json)."""
from __future__ import annotations

from functools import partial

import numpy as np

from .. import estimators
from ..errors import BakeError
from ..lightmap import denoise as denoise_mod, dilation, sh, texels as texels_mod


def check(settings, names, frame_state=None) -> None:
    """BakeError before any work when a directional bake cannot be made as asked."""
    if settings.directional == "none":
        return
    for name in names:
        if not estimators.get(name).directional:
            supported = [n for n in estimators.names() if estimators.get(n).directional]
            raise BakeError(f"setting 'directional' = '{settings.directional}': the {name} estimator does not "
                            f"gather light directions yet (it does with: {', '.join(supported)})")
    if frame_state is not None:
        raise BakeError(f"setting 'directional' = '{settings.directional}': frame ranges bake plain lightmaps "
                        "only (their direct light is re-sampled by frame_direct.py, which has no L1)")


def check_shadowmask(settings, scene, frame_state=None) -> None:
    """BakeError before any work when a named light is not one of the scene's lights, or the
    shadowmask cannot be made as asked (it comes from the shadow rays)."""
    if not settings.shadowmask:
        return
    names = [light.name for light in scene.lights]
    for name in settings.shadowmask:
        if name not in names:
            raise BakeError(f"setting 'shadowmask': light '{name}' is not in the scene (its lights: "
                            f"{', '.join(names) or 'none'})")
    if settings.direct != "sampled":
        raise BakeError(f"setting 'shadowmask' = {list(settings.shadowmask)}: needs direct='sampled' (the mask comes "
                        "from the shadow rays)")
    if frame_state is not None:
        raise BakeError(f"setting 'shadowmask' = {list(settings.shadowmask)}: frame ranges bake plain lightmaps only")


def shadowmask_images(result, mask) -> None:
    """Fill `result.shadowmask_images` ((H, W, 4), dilated, not denoised: a sharp light's mask is
    exact away from penumbrae) from the per-texel visibility (N, 4), and `result.shadowmask`."""
    settings, texels = result.settings, result.texels
    lights = list(settings.shadowmask)
    for lm in texels.lightmaps:
        img, m = texels_mod.to_image(mask[lm.texels], lm, texels.pixel[lm.texels])
        img[..., len(lights):] = 1.0  # unused channels: nothing shadowed
        result.shadowmask_images[lm.name] = dilation.dilate(img, m, settings.margin)
    result.shadowmask = {"lights": lights, "mode": settings.shadowmask_mode, "channels": ["R", "G", "B", "A"],
                         "direct_left_out": settings.shadowmask_mode == "subtract"}


def l1_value(est_l1, direct_l1, share) -> np.ndarray:
    """Per texel L1 (N, 9) in E/π's unit: the estimate over the share traced plus the shadow rays'."""
    total = est_l1 / share if share < 1.0 else np.array(est_l1, np.float64)
    if direct_l1 is not None:
        total += direct_l1
    total /= np.pi
    return total.astype(np.float32)


def make_images(result, l1, plan=None, sharp=None) -> None:
    """Fill `result.l1_images` (sh: (H, W, 9) in sh.L1_CHANNELS order; dominant: (H, W, 4) in
    sh.DOMINANT_CHANNELS order) from the per-texel L1 (N, 9), and `result.directional`. `sharp`:
    the shadow rays' E (N, 3) and L1 (N, 9) of point, spot and sun lights, kept undenoised as the
    plain lightmap keeps them (finishing.Finishing); `plan`: the denoiser's regions and fragments
    (finishing.Denoising)."""
    settings, texels = result.settings, result.texels
    denoise = settings.denoise and denoise_mod.available()
    clamped = 0
    for lm in texels.lightmaps:
        pixel = texels.pixel[lm.texels]
        raw0, mask = texels_mod.to_image(result.value[lm.texels], lm, pixel)
        raw1, _ = texels_mod.to_image(l1[lm.texels], lm, pixel)
        changed = sh.clamp(raw0, sh.from_layout(raw1))
        if denoise:
            out = _denoised(settings, texels, lm, pixel, mask, raw0, raw1, plan, sharp)
        else:
            out = dilation.dilate(raw1, mask, settings.margin)
        l0 = result.images[lm.name]
        layered = sh.from_layout(out)
        changed |= sh.clamp(l0, layered)  # against the lightmap as written, gutter included
        clamped += int(np.count_nonzero(changed & mask))
        if settings.directional == "dominant":
            h, w = mask.shape
            direction, share = sh.dominant(l0.reshape(-1, 3), layered.reshape(-1, 3, 3))
            out = np.concatenate([direction, share[:, None]], axis=1).reshape(h, w, 4)
        result.l1_images[lm.name] = np.ascontiguousarray(out, np.float32)
    result.directional = {"mode": settings.directional, "denoised": bool(denoise), "clamped_texels": clamped,
                          "channels": list(sh.L1_CHANNELS if settings.directional == "sh" else sh.DOMINANT_CHANNELS),
                          "suffix": suffix(settings.directional),
                          # the file's own channel names: sh's by name, dominant's R G B A (engines, Blender)
                          "file_channels": list(sh.L1_CHANNELS if settings.directional == "sh" else "RGBA"),
                          **({"axis_files": list(sh.AXIS_FILES)} if settings.directional == "sh" else {})}


def _denoised(settings, texels, lm, pixel, mask, raw0, raw1, plan, sharp) -> np.ndarray:
    """One lightmap's L1 (H, W, 9), denoised as the module's docstring says."""
    area, _ = texels_mod.to_image(texels.area[lm.texels, None], lm, pixel)
    frag = plan.fragments.get(lm.name) if plan is not None else None
    run = partial(denoise_mod.denoise_lightmap, mask=mask, margin=settings.margin, weights=area[..., 0],
                  regions=plan.regions.get(lm.name) if plan is not None else None, fragments=frag)
    kept = None
    if sharp is not None:
        kept0, _ = texels_mod.to_image(sharp[0][lm.texels] / np.float32(np.pi), lm, pixel)
        kept, _ = texels_mod.to_image(sharp[1][lm.texels] / np.float32(np.pi), lm, pixel)
        raw0 = np.maximum(raw0 - kept0, 0.0)
        raw1 = raw1 - kept
        sh.clamp(raw0, sh.from_layout(raw1))
    if not raw0.any():
        out = np.zeros(raw1.shape, np.float32)
    else:
        base = run(raw0)
        out = np.concatenate([run(raw0 + raw1[..., 3 * a:3 * a + 3]) - base for a in range(3)], axis=-1)
    if kept is not None:
        out += dilation.dilate(kept, mask, settings.margin)
    return out


def suffix(mode: str) -> str:
    """The file name part of a directional map: <object>.<estimator>.<suffix>.exr."""
    return {"sh": "L1", "dominant": "dir"}[mode]
