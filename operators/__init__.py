"""Operators: thin wrappers that gather settings, call the core and report."""
from . import bake

register, unregister = bake.register, bake.unregister
