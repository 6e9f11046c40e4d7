"""Operators: thin wrappers that gather settings, call the core and report."""
import bpy

from . import bake, compare, export, lightmap

classes = bake.classes + lightmap.classes + compare.classes + export.classes


register, unregister = bpy.utils.register_classes_factory(classes)
