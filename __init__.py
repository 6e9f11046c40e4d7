"""detp_bake Blender extension: registration only. The work lives in detp_bake/ (the core),
operators/ and ui/."""
import os

import bpy

from . import operators, ui

_modules = (ui.properties, operators, ui.panels)


def _numba_cache_dir() -> None:
    """Compiled kernels are cached in the extension's user folder, never in the source tree."""
    try:
        path = bpy.utils.extension_path_user(__package__, path="numba_cache", create=True)
    except (ValueError, AttributeError):
        return
    os.environ.setdefault("NUMBA_CACHE_DIR", path)


def register():
    _numba_cache_dir()
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
