"""Operators: thin wrappers that gather settings, call the core and report."""
import bpy

from . import bake, compare, lightmap

classes = bake.classes + lightmap.classes + compare.classes


register, unregister = bpy.utils.register_classes_factory(classes)
