"""What would make lightmaps silently wrong, said after a bake: overlapping lightmap UVs (by object
in an atlas), fragmented charts, UVs outside 0..1, and discs wider than the objects they lie on."""
from __future__ import annotations

import numpy as np

from ..lightmap import charts as charts_mod

OVERLAP_WARNING = 0.01  # a share of texels: Smart UV Project may fold a bent quad over a texel or two
OUTSIDE_WARNING = 0.001  # a share of UV area


def layout_warnings(texels, estimator_settings, radius=None) -> list:
    """What would make lightmaps silently wrong: overlapping lightmap UVs, UVs outside 0..1, and
    (`radius`: the DETP discs' radius per texel) discs wider than the objects they lie on."""
    out = []
    for lm in texels.lightmaps:
        if lm.overlap >= OVERLAP_WARNING:
            out.append(_overlap_warning(lm))
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


def _overlap_warning(lm) -> str:
    """Overlapping lightmap UVs, by object (an atlas's: the objects whose texels overlap)."""
    why = ("(overlapping lightmap UVs, e.g. Array or Mirror copies sharing them): those faces get one shared "
           "value; give every face its own UV space (Unwrap Lightmap UVs, or apply the modifiers that copy faces)")
    if not lm.placement:
        return f"object '{lm.name}': {100 * lm.overlap:.0f} % of its lightmap texels lie under two or more faces {why}"
    named = sorted(((n, p.get("overlap", 0.0)) for n, p in lm.placement.items() if p.get("overlap", 0.0) > 0),
                   key=lambda np_: -np_[1])
    listed = ", ".join(f"'{n}' ({100 * v:.0f} %)" for n, v in named[:6]) + (" …" if len(named) > 6 else "")
    return (f"objects {listed} in atlas '{lm.name}': their lightmap texels lie under two or more faces "
            f"({100 * lm.overlap:.0f} % of the atlas's) {why}")
