"""Operators: thin wrappers that gather settings, call the core and report."""
import bpy

from . import bake, compare, lightmap

classes = bake.classes + lightmap.classes + compare.classes


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
