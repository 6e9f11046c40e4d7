"""The extension as a user gets it. Blender's own extension tool (shipped in the bpy wheel) validates
the source tree and builds this platform's zip with the wheels for the running Python only; the bpy
wheel's Blender, in a fresh process that sees none of the runtime wheels except through the zip,
installs it, bakes the Cornell box through `bpy.ops.detp_bake.bake()`, then disables and removes it.

The wheels are downloaded once into .cache/extension-wheels/ (pip runs only when one is missing).
"""
import importlib.metadata
import io
import json
import re
import os
import platform
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

import extension_build as eb
from conftest import CORNELL, ROOT

PY = f"{sys.version_info.major}.{sys.version_info.minor}"
# One folder per Python: the two Blender lines' suites may run at once (make test).
WHEEL_CACHE = ROOT / ".cache" / "extension-wheels" / f"py{sys.version_info.major}{sys.version_info.minor}"
LINE = next(line for line, py in eb.LINES.items() if py == PY)
HOST = {("linux", "x86_64"): "linux-x64", ("win32", "AMD64"): "windows-x64",
        ("darwin", "arm64"): "macos-arm64"}.get((sys.platform, platform.machine()))


def _bpy_version_dir(bpy) -> Path:
    """`site-packages/bpy/<major>.<minor>` of the bpy wheel (`bpy.__file__` is its scripts/modules copy)."""
    path = Path(bpy.utils.resource_path("LOCAL"))
    assert path.name == "{}.{}".format(*bpy.app.version[:2]) and path.parent.name == "bpy", path
    return path


def _blender_ext(bpy) -> Path:
    path = eb.blender_ext_script(_bpy_version_dir(bpy))
    assert path.is_file(), f"Blender's extension tool is not where the bpy wheel ships it: {path}"
    return path


def _run(*args, **kw):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, **kw)


def test_blender_ext_validates_the_source_tree(bpy):
    proc = _run(_blender_ext(bpy), "validate", ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Success" in proc.stdout


def test_manifest_wheels_are_the_pinned_runtime_wheels_for_every_line_and_platform():
    manifest = eb.manifest()
    assert PY in eb.LINES.values(), f"Python {PY} is not the Python of a supported Blender line {eb.LINES}"
    assert manifest["platforms"] and set(manifest["platforms"]) <= set(eb.PLATFORM_TAGS)
    assert len(set(manifest["wheels"])) == len(manifest["wheels"])
    for line, python in eb.LINES.items():
        pinned = sorted((p.split("==")[0].lower(), p.split("==")[1]) for p in eb.pins(line))
        for plat in manifest["platforms"]:
            listed = sorted(eb.wheel_name_version(w) for w in eb.manifest_wheels(python, plat))
            assert listed == pinned, f"Blender {line} (Python {python}) on {plat}"
    assert {eb.wheel_platform(w) for w in manifest["wheels"]} == set(manifest["platforms"])
    assert {eb.wheel_python(w) for w in manifest["wheels"]} - {None} == set(eb.LINES.values())


@pytest.fixture(scope="module")
def built_zip(bpy, tmp_path_factory):
    """The very zip `make extension` gives users for this line and machine (extension_build.build_zip)."""
    if HOST is None:
        pytest.skip(f"the extension ships no zip for this machine ({sys.platform}, {platform.machine()})")
    dist = tmp_path_factory.mktemp("dist")
    path = eb.build_zip(dist, _blender_ext(bpy), WHEEL_CACHE, LINE, HOST)
    assert path == dist / f"{eb.manifest()['id']}-{eb.manifest()['version']}-blender{LINE}-{HOST}.zip"
    return path


def test_zip_holds_the_add_on_and_this_pythons_wheels_only(bpy, built_zip):
    names = zipfile.ZipFile(built_zip).namelist()
    assert {"__init__.py", "blender_manifest.toml", "detp_bake/run/bake.py", "operators/bake.py",
            "ui/properties.py"} <= set(names)
    assert sorted(n for n in names if n.startswith("wheels/")) == \
        sorted(f"wheels/{Path(w).name}" for w in eb.manifest_wheels(PY, HOST))
    # The add-on's tracked files and the wheels, nothing else: no node_modules, build output, caches or test data.
    tracked = set(eb.shipped_files())
    assert {n for n in names if not n.startswith("wheels/") and not n.endswith("/")} == tracked
    for name in names:
        assert name.split("/")[0] in set(eb.SHIPPED) | {"wheels"}, name
        assert "node_modules" not in name and "__pycache__" not in name, name
        assert not name.endswith((".pyc", ".nbi", ".nbc", ".blend", ".glb", ".exr")), name
    assert not [n for n in names if n.lower().startswith(tuple(f"wheels/{p.lower()}-" for p in eb.BLENDER_PROVIDES))]
    if HOST in eb.CPU_ONLY:  # pyoidn's wheel with the CPU device only, no GPU device or runtime
        wheel = next(n for n in names if n.startswith("wheels/pyoidn-"))
        inner = zipfile.ZipFile(io.BytesIO(zipfile.ZipFile(built_zip).read(wheel))).namelist()
        libs = [Path(n).name for n in inner if n.startswith("pyoidn/oidn/")]
        assert len(libs) == 4 and sum("_device_" in n for n in libs) == 1, libs
        assert any(n.startswith("libOpenImageDenoise_device_cpu.so") for n in libs), libs
        assert not [n for n in libs if re.search(r"cuda|hip|sycl|ur_|umf", n)], libs
    proc = _run(_blender_ext(bpy), "validate", built_zip)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # One Blender line's zip: it says which Blender versions its wheels serve.
    manifest = tomllib.loads(zipfile.ZipFile(built_zip).read("blender_manifest.toml").decode())
    low, high = eb.LINE_VERSIONS[LINE]
    assert manifest["blender_version_min"] == low and manifest.get("blender_version_max") == high


def test_readme_gives_a_size_for_every_line_and_platform():
    sizes = eb.readme_sizes((ROOT / "README.md").read_text())
    assert set(sizes) == {(line, p) for line in eb.LINES for p in eb.manifest()["platforms"]}
    assert all(re.fullmatch(r"\d+ MB", s) for s in sizes.values()), sizes


def test_readme_size_is_the_size_of_the_zip_users_get(bpy, built_zip):
    """README's figure for this line and machine is the built zip's (make extension prints them all)."""
    size = eb.readme_sizes((ROOT / "README.md").read_text())[LINE, HOST]
    assert size == eb.megabytes(built_zip.stat().st_size), \
        f"README.md says {size} for Blender {LINE} on {HOST}; the zip is {built_zip.stat().st_size} bytes " \
        "(make extension prints README's table)"


def test_cpu_only_wheel_keeps_what_pyoidn_loads_and_lists_it(tmp_path):
    """A made-up pyoidn wheel: the cut keeps the Python files, the four CPU libraries, and a RECORD of
    exactly what is left; another platform's wheel, or another package, is left as it is."""
    src = tmp_path / "pyoidn-9.9-py3-none-manylinux2014_x86_64.whl"
    names = ["pyoidn/__init__.py", "pyoidn/oidn/bin/oidnTest", "pyoidn/oidn/lib/libOpenImageDenoise.so",
             "pyoidn/oidn/lib/libOpenImageDenoise.so.2", "pyoidn/oidn/lib/libOpenImageDenoise_core.so.2.5.1",
             "pyoidn/oidn/lib/libOpenImageDenoise_device_cpu.so.2.5.1",
             "pyoidn/oidn/lib/libOpenImageDenoise_device_cuda.so.2.5.1", "pyoidn/oidn/lib/libsycl.so.9",
             "pyoidn/oidn/lib/libtbb.so.12", "pyoidn/oidn/lib/libtbb.so", "pyoidn-9.9.dist-info/METADATA"]
    with zipfile.ZipFile(src, "w") as z:
        for n in names:
            z.writestr(n, n)
        z.writestr("pyoidn-9.9.dist-info/RECORD", "".join(f"{n},sha256=x,{len(n)}\n" for n in names) +
                   "pyoidn-9.9.dist-info/RECORD,,\n")
    out = eb.cpu_only_wheel(src, tmp_path / "cut", "linux-x64")
    kept = {"pyoidn/__init__.py", "pyoidn/oidn/lib/libOpenImageDenoise.so",
            "pyoidn/oidn/lib/libOpenImageDenoise_core.so.2.5.1",
            "pyoidn/oidn/lib/libOpenImageDenoise_device_cpu.so.2.5.1", "pyoidn/oidn/lib/libtbb.so.12",
            "pyoidn-9.9.dist-info/METADATA"}
    with zipfile.ZipFile(out) as z:
        assert set(z.namelist()) == kept | {"pyoidn-9.9.dist-info/RECORD"}
        assert all(z.read(n) == n.encode() for n in kept)
        record = {r.split(",")[0] for r in z.read("pyoidn-9.9.dist-info/RECORD").decode().splitlines()}
    assert record == kept | {"pyoidn-9.9.dist-info/RECORD"}
    assert eb.cpu_only_wheel(src, tmp_path / "cut2", "windows-x64") == src


def test_a_checkouts_build_output_stays_out_of_the_zip(tmp_path, monkeypatch):
    """Files a checkout gathers (viewer/node_modules, a stray file in the core) are not tracked: not staged."""
    stray = ROOT / "detp_bake" / "_stray_build_output.tmp"
    stray.write_text("not tracked")
    try:
        src = eb.stage_source(tmp_path / "src", [], "linux-x64", "4.5")
    finally:
        stray.unlink()
    staged = {str(p.relative_to(src)) for p in src.rglob("*") if p.is_file()}
    assert "detp_bake/_stray_build_output.tmp" not in staged
    assert not any(s.startswith(("viewer/", "tests/", "docs/", "sample_scenes/")) for s in staged)
    assert staged - {"blender_manifest.toml"} == {f for f in eb.shipped_files() if f != "blender_manifest.toml"}


def _blender_own_site(bpy) -> Path:
    """Blender's own Python's site-packages, which a real Blender has on sys.path (OpenImageIO,
    PyOpenColorIO, MaterialX, pxr...): the bpy wheel keeps a copy of it, off sys.path."""
    path = _bpy_version_dir(bpy) / "python" / "lib" / f"python{PY}" / "site-packages"
    assert path.is_dir(), f"the bpy wheel has no copy of Blender's own site-packages: {path}"
    return path


def _blender_like_site(bpy, dst: Path) -> Path:
    """The test environment's site-packages without the extension's runtime wheels, as links, and
    Blender's own site-packages on the path, as in a real Blender."""
    site_packages = _bpy_version_dir(bpy).parent.parent
    hidden = {f.parts[0] for name in eb.RUNTIME for f in importlib.metadata.distribution(name).files
              if f.parts[0] != ".."}
    dst.mkdir()
    for entry in site_packages.iterdir():
        if entry.name not in hidden and entry.suffix != ".pth":
            (dst / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())
    (dst / "blender_own_python.pth").write_text(f"{_blender_own_site(bpy)}\n")
    return dst


def test_install_bake_disable_uninstall(bpy, built_zip, tmp_path):
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("BLENDER_USER_", "NUMBA_", "PYTHON"))}
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "blender-user")
    out, result = tmp_path / "lightmaps", tmp_path / "result.json"
    site = _blender_like_site(bpy, tmp_path / "site")
    proc = subprocess.run([sys.executable, "-S", str(ROOT / "tests" / "extension_session.py"), site, built_zip,
                           CORNELL, out, result], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=900)
    log = f"--- stdout\n{proc.stdout[-4000:]}\n--- stderr\n{proc.stderr[-4000:]}"
    assert proc.returncode == 0 and result.exists(), log
    r = json.loads(result.read_text())
    assert "error" not in r, r.get("error", "") + log
    assert r["preinstalled"] == [], "the Blender session must see the bundled wheels only through the zip"
    own = str(_blender_own_site(bpy))
    assert all(str(origin).startswith(own) for origin in r["blender_provides"].values()), r["blender_provides"]

    assert r["install"] == ["FINISHED"] and r["installed_dir"], log
    state = r["after_install"]
    assert state["addon_enabled"] and "bake" in state["ops"] and state["types"] \
        and "Scene" in state["properties"], state

    assert r["bake"] == ["FINISHED"], log
    assert r["exr"] and all(n.endswith(".exr") and (out / n).stat().st_size > 0 for n in r["exr"]), r["exr"]
    assert {"embreex", "numba", "llvmlite", "OpenImageIO", "pyoidn"} <= set(r["imported_by_bake"]), log
    for name, path in r["module_files"].items():  # from the bundled wheels, or Blender's own Python
        where = [own] if name in eb.BLENDER_PROVIDES else r["wheel_site_packages"]
        assert any(path.startswith(sp) for sp in where), (name, path)
    # numba's cache: the extension's user folder, one subfolder per state of the core's sources.
    assert Path(r["numba_cache_dir"]).parent == Path(r["numba_user_path"]), r["numba_cache_dir"]
    assert len(Path(r["numba_cache_dir"]).name) == 12
    assert r["numba_cache_files"] > 0

    assert r["disable"] == ["FINISHED"]
    for state in (r["after_disable"], r["after_uninstall"]):
        assert state == {"addon_enabled": False, "ops": [], "types": [], "properties": []}, state
    assert r["uninstall"] == ["FINISHED"]
    assert not r["left_in_repo"]
    # Nothing left outside the extension's own user folder (its compiled-kernel cache) once it is removed,
    # but Blender's own extension cache.
    left = [f for f in r["user_files_added"]
            if not f.startswith((r["extension_user_dir"] + os.sep, os.path.join("extensions", ".cache") + os.sep))]
    assert not left, (r["extension_user_dir"], left)
    assert not [n for n in r["left_wheels"] if n.split("-")[0].split(".")[0].lower() in
                {p.lower() for p in eb.BUNDLED}], r["left_wheels"]
