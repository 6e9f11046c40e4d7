"""The Blender adapter, the only part of detp_bake that imports `bpy`: Blender data → `scene.Scene`
(export), .blend files for the command line (files), the scene frame by frame (frames), baked
images back into materials (lightmaps), the baked probes on moving objects and in the viewport
(probe_light, probe_view), the lightmaps refining live while a job runs (preview),
lightmap UV layers (uv), and Cycles' own
bake as the reference (reference).

Export reads the scene as F12 renders it (evaluation). Applying a lightmap adds a node frame named
FRAME_NAME to each material and remembers on the object what it changed, so `revert` restores the
materials, slots and images exactly as they were.
"""
from .common import DEFAULT_ALBEDO, DEFAULT_UV, FRAME_NAME, REVERT_KEY
from .evaluation import rendered_names
from .export import export_scene, material_albedo_emission, scene_bounces
from .files import open_blend, save_blend
from .frames import frame_exporter, frame_kept
from .lightmaps import apply_all, apply_lightmap, load_image, revert, shared_materials
from .preview import LivePreview
from .probe_light import apply_marked, apply_probes
from .reference import cycles_bake
from .uv import ensure_lightmap_uv, lightmap_pack, remove_uv_layers, unwrap_into, xatlas_unwrap

__all__ = ["DEFAULT_ALBEDO", "DEFAULT_UV", "FRAME_NAME", "REVERT_KEY", "export_scene", "material_albedo_emission",
           "scene_bounces", "apply_all", "shared_materials", "LivePreview", "apply_lightmap", "load_image", "revert",
           "apply_marked", "apply_probes", "cycles_bake", "ensure_lightmap_uv", "lightmap_pack", "remove_uv_layers", "unwrap_into", "xatlas_unwrap",
           "rendered_names", "open_blend",
           "save_blend", "frame_exporter", "frame_kept"]
