"""One Blender session for tests/test_extension.py, run as `python -S extension_session.py SITE ZIP
SCENE OUT RESULT_JSON` in a fresh process: installs the extension zip into the bpy wheel's Blender,
bakes the scene through `bpy.ops.detp_bake.bake()`, disables and uninstalls the extension, and
writes what it saw to RESULT_JSON (the test judges it).

SITE is a site-packages folder holding bpy and what Blender itself bundles (its own Python's
site-packages, OpenImageIO among them), but none of the extension's runtime wheels: those can only
come from the zip, as in a real Blender.
"""
import glob
import importlib
import importlib.util
import json
import os
import site
import sys
import time
import traceback

RUNTIME = ("embreex", "OpenImageIO", "numba", "llvmlite", "xatlas", "pyoidn")  # as extension_build.RUNTIME
BLENDER_PROVIDES = ("OpenImageIO",)  # as extension_build.BLENDER_PROVIDES: Blender's own, not in the zip
REPO = "user_default"
PKG = "detp_bake"
MODULE = f"bl_ext.{REPO}.{PKG}"


def registered(bpy):
    return {
        "addon_enabled": MODULE in bpy.context.preferences.addons,
        "ops": sorted(dir(bpy.ops.detp_bake)),
        "types": sorted(n for n in dir(bpy.types) if n.startswith("DETPBAKE_")),
        "properties": [t for t in ("Scene", "Object", "Mesh", "Material", "Image", "WindowManager")
                       if hasattr(getattr(bpy.types, t), "detp_bake")],
    }


def files_under(root):
    """Every file below `root`, relative to it."""
    return sorted(os.path.relpath(os.path.join(d, f), root) for d, _, fs in os.walk(root) for f in fs)


def main(site_dir, zip_path, scene_path, out_dir, result_path):
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(os.path.abspath(__file__))]
    site.addsitedir(site_dir)
    r = {"preinstalled": [n for n in RUNTIME if n not in BLENDER_PROVIDES and importlib.util.find_spec(n) is not None],
         "blender_provides": {n: getattr(importlib.util.find_spec(n), "origin", None) for n in BLENDER_PROVIDES},
         "seconds": {}}
    clock = [time.perf_counter()]

    def lap(name):
        now = time.perf_counter()
        r["seconds"][name] = round(now - clock[0], 2)
        clock[0] = now

    def dump():
        with open(result_path, "w") as fh:
            json.dump(r, fh, indent=1)

    user_root = os.environ["BLENDER_USER_RESOURCES"]
    try:
        import bpy
        before = set(files_under(user_root))
        r["blender"] = bpy.app.version_string
        repos = [repo.module for repo in bpy.context.preferences.extensions.repos]
        repo = bpy.context.preferences.extensions.repos[repos.index(REPO)]
        r["install"] = sorted(bpy.ops.extensions.package_install_files(
            filepath=zip_path, repo=REPO, enable_on_install=True))
        r["installed_dir"] = os.path.isdir(os.path.join(repo.directory, PKG))
        r["after_install"] = registered(bpy)
        lap("install")

        bpy.ops.wm.open_mainfile(filepath=scene_path)
        settings = bpy.context.scene.detp_bake
        settings.photons = 20000
        settings.resolution = 16
        settings.output_directory = out_dir
        r["bake"] = sorted(bpy.ops.detp_bake.bake())
        lap("bake")
        r["exr"] = sorted(os.path.basename(p) for p in glob.glob(os.path.join(out_dir, "*.exr")))
        r["imported_by_bake"] = sorted(n for n in RUNTIME if n in sys.modules)
        for name in RUNTIME:  # every bundled wheel must load in this Blender
            importlib.import_module(name)
        r["module_files"] = {n: sys.modules[n].__file__ for n in RUNTIME}
        r["extensions_dir"] = os.path.dirname(repo.directory)
        r["numba_cache_dir"] = os.environ.get("NUMBA_CACHE_DIR")
        r["numba_user_path"] = bpy.utils.extension_path_user(MODULE, path="numba_cache")
        r["numba_cache_files"] = len(glob.glob(os.path.join(r["numba_user_path"], "**", "*.nbi"), recursive=True))
        site_packages = [p for p in sys.path if p.startswith(r["extensions_dir"]) and p.endswith("site-packages")]
        r["wheel_site_packages"] = site_packages

        r["disable"] = sorted(bpy.ops.preferences.addon_disable(module=MODULE))
        r["after_disable"] = registered(bpy)
        r["uninstall"] = sorted(bpy.ops.extensions.package_uninstall(repo_index=repos.index(REPO), pkg_id=PKG))
        r["after_uninstall"] = registered(bpy)
        lap("disable_uninstall")
        r["left_in_repo"] = os.path.exists(os.path.join(repo.directory, PKG))
        r["user_files_added"] = sorted(set(files_under(user_root)) - before)
        r["extension_user_dir"] = os.path.relpath(bpy.utils.extension_path_user(MODULE), user_root)
        r["left_wheels"] = sorted(n for sp in site_packages if os.path.isdir(sp) for n in os.listdir(sp))
    except BaseException:
        r["error"] = traceback.format_exc()
    dump()


if __name__ == "__main__":
    main(*sys.argv[1:])
