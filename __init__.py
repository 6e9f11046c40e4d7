"""detp_bake Blender extension: registration only. The work lives in detp_bake/ (the core),
operators/ and ui/."""
import os

import bpy


def _user_dir(*parts, create=False):
    try:
        return bpy.utils.extension_path_user(__package__, path=os.path.join(*parts) if parts else "", create=create)
    except (ValueError, AttributeError):  # not installed as an extension (tests, legacy add-on)
        return None


def _sources_key() -> str:
    """A short hash of the core's sources. numba checks only the date of a kernel's own file, not
    of the files whose helpers it inlines, so after an update a kernel could load stale machine
    code: one cache folder per state of the sources never can."""
    import hashlib

    core = os.path.join(os.path.dirname(__file__), "detp_bake")
    digest = hashlib.sha1()
    for folder, dirs, files in sorted(os.walk(core)):
        dirs.sort()
        for name in sorted(files):
            if name.endswith(".py"):
                with open(os.path.join(folder, name), "rb") as f:
                    digest.update(f.read())
    return digest.hexdigest()[:12]


def _numba_cache_dir() -> None:
    """Compiled kernels are cached in the extension's user folder (or the folder the preferences
    name), never in the installed source tree, in a subfolder per state of the core's sources.
    Numba reads this when the core is first imported."""
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    base = _user_dir(create=True)
    if base is None:
        return
    chosen = os.path.join(base, "cache_directory.txt")
    path = open(chosen).read().strip() if os.path.isfile(chosen) else ""
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(path or _user_dir("numba_cache", create=True), _sources_key())


_numba_cache_dir()

from . import operators, ui  # noqa: E402  (after the cache folder is chosen)
from .operators import cli_command  # noqa: E402

_modules = (ui.properties, ui.preferences, operators, ui.panels, cli_command)


def register():
    for module in _modules:
        module.register()
    if not bpy.app.background:  # interactive: compile the kernels now, not at the first click
        from .detp_bake.run import warmup
        warmup.start()


def unregister():
    from .detp_bake.run import job, warmup
    running = job.running()
    if running is not None and hasattr(running, "cancel"):
        running.cancel()
    warmup.stop()
    warmup.wait()
    for module in reversed(_modules):
        module.unregister()
    job.release_memory()
