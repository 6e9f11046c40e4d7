"""Operators: thin wrappers that gather settings, call the core and report."""
import bpy

from . import bake, compare, export, lightmap

classes = bake.classes + lightmap.classes + compare.classes + export.classes


_register, _unregister = bpy.utils.register_classes_factory(classes)


def register():
    from ..detp_bake.blender import probe_light
    _register()
    probe_light.register_handler()  # probe-lit objects follow the frame


def unregister():
    from ..detp_bake.blender import probe_light
    probe_light.unregister_handler()
    _unregister()
