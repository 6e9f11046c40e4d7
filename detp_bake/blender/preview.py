"""The lightmaps refining live while a job runs: each baked object shows a float image that the
job's Preview events overwrite, wired through the very node frame Apply uses (lightmaps.py).

An object that shows no lightmap yet gets one (`apply_lightmap`), which `end` reverts exactly; an
object that already shows one keeps its frame and only its Image Texture nodes are pointed at the
preview image, and `end` points them back. So Esc, an error, or a finished bake (which then
applies its files as usual) leave the materials as they were before the job.
"""
from __future__ import annotations

import json

import bpy
import numpy as np

from .atlas import ATLAS_UV, members as atlas_members
from .common import DEFAULT_UV, FRAME_NAME, REVERT_KEY
from .lightmaps import apply_lightmap, revert, shared_materials

PREFIX = "detp_bake preview "


class LivePreview:
    def __init__(self, bl_scene, objects: list, uv_layer):
        """`objects`: names of the objects baked; `uv_layer`: one name, {object name: name} or None."""
        self.scene = bl_scene
        self.names = list(objects)
        self.uv_layer = uv_layer
        self.images: dict = {}  # object name -> image datablock
        self.applied: list = []  # objects we wired (revert them)
        self.swapped: list = []  # (material name, node name, image name it showed)
        self.updates = 0

    def _image(self, name: str, shape, layer=None) -> "bpy.types.Image":
        h, w = shape[:2]
        img = self.images.get(name)
        if img is not None and tuple(img.size) == (w, h):
            return img
        img = bpy.data.images.new(f"{PREFIX}{name}", w, h, alpha=False, float_buffer=True)
        self.images[name] = img
        obj = self.scene.objects.get(name)
        if obj is None:
            return img
        if REVERT_KEY in obj:
            self._swap(obj, img)
        else:
            layer = layer or (self.uv_layer.get(name) if isinstance(self.uv_layer, dict) else self.uv_layer)
            shared = bool(shared_materials(obj, [self.scene.objects[n] for n in self.names
                                                 if n in self.scene.objects]))
            apply_lightmap(obj, img, layer or DEFAULT_UV, shared)
            self.applied.append(name)
        return img

    def _swap(self, obj, img) -> None:
        for slot in obj.material_slots:
            mat = slot.material
            if mat is None or mat.node_tree is None or mat.node_tree.nodes.get(FRAME_NAME) is None:
                continue
            frame = mat.node_tree.nodes[FRAME_NAME]
            for node in mat.node_tree.nodes:
                if node.parent == frame and node.type == "TEX_IMAGE" and node.image is not img:
                    self.swapped.append((mat.name, node.name, node.image.name if node.image else None))
                    node.image = img

    def update(self, images: dict) -> None:
        """Write a Preview event's images ({lightmap: (H, W, 3) E/π, row 0 at the bottom}) and
        redraw. An atlas's image is written once, into an image of each of its objects."""
        atlases = atlas_members(self.scene)
        for lightmap, picture in images.items():
            rgba = None
            for name in atlases.get(lightmap, [lightmap]):
                if name not in self.names:
                    continue
                img = self._image(name, picture.shape, ATLAS_UV if lightmap in atlases else None)
                if rgba is None:
                    rgba = np.ones(picture.shape[:2] + (4,), np.float32)
                    rgba[..., :3] = picture
                img.pixels.foreach_set(rgba.ravel())
                img.update()
        self.updates += 1
        if not bpy.app.background:
            for window in bpy.context.window_manager.windows:
                for area in window.screen.areas:
                    if area.type in ("VIEW_3D", "IMAGE_EDITOR"):
                        area.tag_redraw()

    def end(self) -> None:
        """Put every material back as it was before the preview."""
        for name in self.applied:
            obj = self.scene.objects.get(name)
            if obj is not None and REVERT_KEY in obj and \
                    json.loads(obj[REVERT_KEY]).get("image") == self.images[name].name:
                revert(obj)
        for mat_name, node_name, image_name in self.swapped:
            mat = bpy.data.materials.get(mat_name)
            node = mat.node_tree.nodes.get(node_name) if mat is not None else None
            if node is not None:
                node.image = bpy.data.images.get(image_name) if image_name else None
        names = []
        for img in self.images.values():
            try:
                names.append(img.name)
            except ReferenceError:  # revert removed it already
                pass
        for image_name in names:
            img = bpy.data.images.get(image_name)
            if img is not None and img.users == 0:
                bpy.data.images.remove(img)
        self.images, self.applied, self.swapped = {}, [], []
