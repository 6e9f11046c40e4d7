"""Cycles' own Diffuse bake of the same objects, in this process: the reference every quality test and
benchmark compares against."""
from __future__ import annotations

from typing import Iterable, Optional

import bpy
import numpy as np

from ..errors import BakeError
from .common import DEFAULT_UV


def cycles_bake(bl_scene, object_names: Iterable[str], uv_name: str = DEFAULT_UV, resolution: int = 64,
                samples: int = 256, bounces: Optional[int] = None, margin: int = 0,
                seed: int = 0) -> dict:
    """Cycles' own Diffuse bake (DIRECT+INDIRECT, no COLOR: E/π, our unit) of each object, as
    (H, W, 3) float32 arrays with row 0 at the bottom. Render settings, selection, nodes and
    images are restored afterwards; this is the reference every quality test compares against."""
    cyc = bl_scene.cycles
    saved = {k: getattr(cyc, k) for k in ("device", "samples", "use_adaptive_sampling", "use_denoising",
                                          "sample_clamp_direct", "sample_clamp_indirect",
                                          "diffuse_bounces", "seed")}
    engine = bl_scene.render.engine
    view_layer = bpy.context.view_layer
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    out = {}
    try:
        bl_scene.render.engine = "CYCLES"
        cyc.device = "CPU"
        cyc.samples = int(samples)
        cyc.use_adaptive_sampling = False
        cyc.use_denoising = False
        cyc.sample_clamp_direct = 0.0
        cyc.sample_clamp_indirect = 0.0
        cyc.seed = int(seed)
        if bounces is not None:
            cyc.diffuse_bounces = int(bounces)
        for name in object_names:
            obj = bl_scene.objects[name]
            img = bpy.data.images.new(f"detp_bake reference {name}", resolution, resolution,
                                      alpha=False, float_buffer=True)
            added = []
            try:
                for slot in obj.material_slots:
                    mat = slot.material
                    if mat is None or mat.node_tree is None:
                        raise BakeError(f"object '{name}': Cycles bake needs node materials in every slot")
                    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
                    node.image = img
                    previous = mat.node_tree.nodes.active
                    mat.node_tree.nodes.active = node
                    added.append((mat, node, previous))
                for o in view_layer.objects:
                    o.select_set(False)
                obj.select_set(True)
                view_layer.objects.active = obj
                res = bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"},
                                          uv_layer=uv_name, margin=int(margin), margin_type="EXTEND",
                                          use_clear=True, target="IMAGE_TEXTURES")
                if "FINISHED" not in res:
                    raise BakeError(f"object '{name}': Cycles bake did not finish")
                px = np.empty(resolution * resolution * 4, np.float32)
                img.pixels.foreach_get(px)
                out[name] = px.reshape(resolution, resolution, 4)[..., :3].copy()
            finally:
                for mat, node, previous in added:
                    mat.node_tree.nodes.remove(node)
                    if previous is not None:
                        mat.node_tree.nodes.active = previous
                bpy.data.images.remove(img)
    finally:
        for k, v in saved.items():
            setattr(cyc, k, v)
        bl_scene.render.engine = engine
        for o in view_layer.objects:
            o.select_set(o in selected)
        view_layer.objects.active = active
    return out
