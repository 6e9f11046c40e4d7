"""The wheels the detp_bake extension bundles, and how its zips are built: used by `make extension`
and tests/test_extension.py. Not part of the extension (the build excludes tests/).

    python tests/extension_build.py wheels DEST   # download every wheel blender_manifest.toml lists
    python tests/extension_build.py zips DIST     # one zip per Blender line and platform, with sizes

Every wheel comes from `pip download --only-binary=:all: --no-deps --platform ... --python-version
...` with the pins of requirements/blender-<line>.txt, and the result must be exactly the manifest's
`wheels` list: a pin changed in requirements/ without the manifest (or the reverse) is an error
that names the difference. numpy and OpenImageIO are Blender's own and are never bundled (BLENDER_PROVIDES).
"""
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "blender_manifest.toml"

# Blender LTS line -> the CPython it bundles.
LINES = {"4.5": "3.11", "5.2": "3.13"}
# Blender LTS line -> the Blender versions its zip installs on (min, max exclusive; None: no max):
# the 4.5 line's wheels are built for CPython 3.11 and numpy 1.26, the 5.2 line's for 3.13 and numpy 2.
LINE_VERSIONS = {"4.5": ("4.5.0", "5.0.0"), "5.2": ("5.2.0", None)}

# What the extension imports at run time besides Blender's own numpy (bpy is Blender itself).
RUNTIME = ("embreex", "OpenImageIO", "numba", "llvmlite", "xatlas", "pyoidn")
# What Blender itself provides of these, on every line: Blender 4.5 and 5.2 install OpenImageIO's Python
# module into their own Python (<version>/python/lib/python3.x/site-packages/OpenImageIO, on sys.path;
# the bpy wheel keeps a copy of that folder: OIIO 3.0.19 for 4.5, 3.1.13 for 5.2), and it writes the
# same bytes as the pinned wheel. Inside Blender the add-on imports Blender's; outside it, the wheel of
# requirements/. The zips do not bundle it.
BLENDER_PROVIDES = ("OpenImageIO",)
BUNDLED = tuple(p for p in RUNTIME if p not in BLENDER_PROVIDES)

# Blender platform -> pip --platform tags, most preferred first.
# - linux-x64: Blender 4.5+ needs glibc 2.28, so manylinux_2_28 and older.
# - macos-arm64: embreex 4.4 wheels need macOS 13 (numba/llvmlite 12, the rest 11).
# - macos-x64 is left out: numba >= 0.63 and llvmlite >= 0.46 have no Intel-mac wheels (the last are
#   numba 0.62.1 / llvmlite 0.45.1), and Blender 5.x has no Intel-mac build at all.
PLATFORM_TAGS = {
    "linux-x64": [f"manylinux_2_{minor}_x86_64" for minor in range(28, 16, -1)] + ["manylinux2014_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": ["macosx_13_0_arm64"],
}


def manifest() -> dict:
    with open(MANIFEST, "rb") as fh:
        return tomllib.load(fh)


def wheel_platform(filename: str) -> str:
    """The Blender platform of a wheel file name (only the ones this extension ships)."""
    tag = Path(filename).stem.split("-")[-1]
    if "manylinux" in tag and tag.endswith("x86_64"):
        return "linux-x64"
    if tag == "win_amd64":
        return "windows-x64"
    if tag.startswith("macosx_") and tag.endswith("_arm64"):
        return "macos-arm64"
    if tag.startswith("macosx_") and tag.endswith("_x86_64"):
        return "macos-x64"
    raise ValueError(f"unexpected platform tag in wheel {filename!r}")


def wheel_python(filename: str) -> str | None:
    """'3.11' for a cp311 wheel; None for a py3 wheel (pyoidn: one wheel serves every line)."""
    tag = Path(filename).stem.split("-")[-3]
    if tag == "py3":
        return None
    m = re.fullmatch(r"cp3(\d+)", tag)
    if not m:
        raise ValueError(f"unexpected Python tag in wheel {filename!r}")
    return f"3.{m.group(1)}"


def wheel_name_version(filename: str) -> tuple[str, str]:
    name, version = Path(filename).stem.split("-")[:2]
    return name.lower().replace("_", "-"), version


def manifest_wheels(python: str | None = None, platform: str | None = None) -> list[str]:
    """The manifest's wheel paths ('./wheels/x.whl'), optionally for one Python and one platform."""
    return [w for w in manifest().get("wheels", [])
            if (python is None or wheel_python(w) in (python, None))
            and (platform is None or wheel_platform(w) == platform)]


def pins(line: str) -> list[str]:
    """`name==version` of every bundled runtime package (BUNDLED) in requirements/blender-<line>.txt."""
    found = {}
    for raw in (ROOT / "requirements" / f"blender-{line}.txt").read_text().splitlines():
        req = raw.split("#")[0].strip()
        if "==" in req:
            name, version = (s.strip() for s in req.split("=="))
            found[name.lower()] = f"{name}=={version}"
    missing = [p for p in RUNTIME if p.lower() not in found]
    if missing:
        raise SystemExit(f"requirements/blender-{line}.txt pins none of {missing}")
    return [found[p.lower()] for p in BUNDLED]


def download(dest: Path, python: str, platform: str, quiet: bool = True) -> None:
    line = next(line for line, py in LINES.items() if py == python)
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
           "--python-version", python, "--implementation", "cp", "--dest", str(dest)]
    for tag in PLATFORM_TAGS[platform]:
        cmd += ["--platform", tag]
    if quiet:
        cmd.append("-q")
    print(f"pip download: Python {python} (Blender {line}), {platform}", flush=True)
    subprocess.run(cmd + pins(line), check=True)


def check(dest: Path, expected: list[str], exact: bool) -> None:
    """`dest` holds the expected wheel files (and nothing else when `exact`)."""
    want = {Path(w).name for w in expected}
    have = {p.name for p in Path(dest).glob("*.whl")}
    missing, extra = sorted(want - have), sorted(have - want) if exact else []
    if missing or extra:
        msg = ["the downloaded wheels differ from blender_manifest.toml's `wheels` list"]
        msg += [f"  listed, not downloaded: {m}" for m in missing]
        msg += [f"  downloaded, not listed: {m}" for m in extra]
        msg.append("  (update `wheels` in blender_manifest.toml to match requirements/blender-*.txt)")
        raise SystemExit("\n".join(msg))


def download_all(dest: Path) -> None:
    """Every wheel for every Blender line and every platform of the manifest, exactly those listed."""
    platforms = manifest()["platforms"]
    dest.mkdir(parents=True, exist_ok=True)
    for python in LINES.values():
        for platform in platforms:
            download(dest, python, platform)
    check(dest, manifest_wheels(), exact=True)


def download_cached(cache: Path, python: str, platform: str) -> list[Path]:
    """The manifest's wheels for one Python and platform, from `cache` (pip only runs when one is missing)."""
    expected = manifest_wheels(python, platform)
    if not all((cache / Path(w).name).exists() for w in expected):
        cache.mkdir(parents=True, exist_ok=True)
        download(cache, python, platform)
    check(cache, expected, exact=False)
    return [cache / Path(w).name for w in expected]


# pyoidn's Linux wheel carries OIDN's GPU devices (SYCL, HIP, CUDA and the SYCL runtime: libsycl,
# libur_*, libumf), its command-line tools and CMake files beside the CPU device, and each library
# three times over (a zip holds no symlinks). The add-on runs OIDN on the CPU only (lightmap/denoise.py),
# so its zip gets the wheel with just what pyoidn loads: the library it opens, the core (with the
# networks' weights), the CPU device, which OIDN's core finds beside itself, and TBB by its soname.
# The Windows and macOS wheels are bundled as published: nothing here can load them to check a cut.
CPU_ONLY = {"linux-x64": re.compile(r"pyoidn/oidn/lib/lib(OpenImageDenoise\.so|OpenImageDenoise_core\.so\.[\d.]+"
                                    r"|OpenImageDenoise_device_cpu\.so\.[\d.]+|tbb\.so\.12)")}


def cpu_only_wheel(wheel: Path, dest: Path, platform: str) -> Path:
    """`wheel` as dest/<same name>, without pyoidn's files that the CPU device never loads (CPU_ONLY),
    its RECORD listing exactly what is left. Any other wheel, or platform, is returned as it is."""
    import zipfile
    if not wheel.name.startswith("pyoidn-") or platform not in CPU_ONLY:
        return wheel

    def keep(name: str) -> bool:
        return not name.startswith("pyoidn/oidn/") or bool(CPU_ONLY[platform].fullmatch(name))

    dest.mkdir(parents=True, exist_ok=True)
    out = dest / wheel.name
    with zipfile.ZipFile(wheel) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        record = next(n for n in src.namelist() if n.endswith(".dist-info/RECORD"))
        for info in src.infolist():
            if keep(info.filename) and info.filename != record:
                dst.writestr(info, src.read(info))  # the entry's date and mode bits kept
        lines = [r for r in src.read(record).decode().splitlines() if r and keep(r.split(",")[0])]
        dst.writestr(src.getinfo(record), "\n".join(lines) + "\n")
    return out


def blender_ext_script(bpy_version_dir: Path) -> Path:
    """Blender's extension tool, shipped inside the bpy wheel (`bpy/<major>.<minor>/`) as a standalone script."""
    return Path(bpy_version_dir) / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"


# What the extension is: the add-on's own tracked files, nothing else. A checkout where the suite ran
# also holds viewer/node_modules, build output and caches; none of it may reach a user's zip.
SHIPPED = ("__init__.py", "blender_manifest.toml", "README.md", "detp_bake", "operators", "ui")


def shipped_files() -> list[str]:
    """The repository's tracked files under SHIPPED (git ls-files): what every zip is built from."""
    proc = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z", "--", *SHIPPED],
                          capture_output=True, text=True, check=True)
    files = [f for f in proc.stdout.split("\0") if f]
    if "__init__.py" not in files or "blender_manifest.toml" not in files:
        raise SystemExit(f"git ls-files in {ROOT} lists no extension: build from a git checkout")
    return files


def stage_source(dst: Path, wheels: list[Path], platform: str, line: str | None = None) -> Path:
    """A copy of the extension's source (shipped_files) whose manifest lists only `wheels` and `platform`,
    with those wheels in place: `blender_ext.py build` on it builds just that platform's zip.
    `line`: the manifest also names the Blender versions of that line (LINE_VERSIONS)."""
    for name in shipped_files():
        if (ROOT / name).is_file():  # a tracked file deleted in the work tree is not shipped
            (dst / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dst / name)
    (dst / "wheels").mkdir()
    for w in wheels:
        shutil.copy2(w, dst / "wheels" / w.name)
    text = MANIFEST.read_text()
    listed = "".join(f'\n  "./wheels/{w.name}",' for w in wheels)
    text, n_w = re.subn(r"(?ms)^wheels\s*=\s*\[.*?\]", f"wheels = [{listed}\n]", text)
    text, n_p = re.subn(r"(?ms)^platforms\s*=\s*\[.*?\]", f'platforms = ["{platform}"]', text)
    assert n_w == 1 and n_p == 1, "blender_manifest.toml: expected one `wheels` and one `platforms` list"
    if line is not None:
        low, high = LINE_VERSIONS[line]
        text, n_v = re.subn(r'(?m)^blender_version_min\s*=.*$', f'blender_version_min = "{low}"' +
                            (f'\nblender_version_max = "{high}"' if high else ""), text)
        assert n_v == 1, "blender_manifest.toml: expected one blender_version_min"
    (dst / "blender_manifest.toml").write_text(text)
    return dst


def zip_name(line: str, platform: str) -> str:
    info = manifest()
    return f"{info['id']}-{info['version']}-blender{line}-{platform}.zip"


def build_zip(dist: Path, blender_ext: Path, cache: Path, line: str, platform: str) -> Path:
    """The zip users get for one Blender line and platform, with that line's wheels only:
    dist/<id>-<version>-blender<line>-<platform>.zip (`make extension` and tests/test_extension.py)."""
    import tempfile
    dist.mkdir(parents=True, exist_ok=True)
    out = dist / zip_name(line, platform)
    with tempfile.TemporaryDirectory() as tmp:
        wheels = [cpu_only_wheel(w, Path(tmp) / "cpu-only", platform)
                  for w in download_cached(cache, LINES[line], platform)]
        src = stage_source(Path(tmp) / "src", wheels, platform, line)
        subprocess.run([sys.executable, str(blender_ext), "build", "--source-dir", str(src),
                        "--output-filepath", str(out)], check=True, stdout=subprocess.DEVNULL)
    return out


def megabytes(size: int) -> str:
    """A zip's size as README's table writes it."""
    return f"{size / 1e6:.0f} MB"


def size_table(sizes: dict) -> list[str]:
    """README's table of zip sizes (Markdown rows) from {(line, platform): bytes}."""
    platforms = manifest()["platforms"]
    rows = ["| Blender line | " + " | ".join(platforms) + " |", "|---" * (len(platforms) + 1) + "|"]
    for line in LINES:
        rows.append(f"| {line} | " + " | ".join(megabytes(sizes[line, p]) for p in platforms) + " |")
    return rows


def readme_sizes(text: str) -> dict:
    """{(line, platform): 'N MB'} from README's table of zip sizes (size_table's form)."""
    platforms = manifest()["platforms"]
    head = "| Blender line | " + " | ".join(platforms) + " |"
    lines = text.splitlines()
    if head not in lines:
        raise ValueError(f"README.md has no table of zip sizes headed {head!r}")
    found = {}
    for row in lines[lines.index(head) + 2:]:
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        if not row.startswith("|") or cells[0] not in LINES:
            break
        found.update({(cells[0], p): c for p, c in zip(platforms, cells[1:])})
    return found


def build_zips(dist: Path, blender_ext: Path, cache: Path) -> list[tuple[Path, int]]:
    """Every line's and platform's zip (build_zip), then README's table of their sizes. Returns
    [(zip, bytes)]."""
    built, sizes = [], {}
    for line in LINES:
        for platform in manifest()["platforms"]:
            out = build_zip(dist, blender_ext, cache, line, platform)
            built.append((out, out.stat().st_size))
            sizes[line, platform] = out.stat().st_size
            print(f"{out.name}: {out.stat().st_size} bytes", flush=True)
    print("\nREADME.md, zip sizes:\n" + "\n".join(size_table(sizes)), flush=True)
    return built


if __name__ == "__main__":
    if len(sys.argv) < 3 or sys.argv[1] not in ("wheels", "zips"):
        raise SystemExit(__doc__)
    if sys.argv[1] == "wheels":
        download_all(Path(sys.argv[2]))
    else:  # zips DIST BLENDER_EXT
        build_zips(Path(sys.argv[2]), Path(sys.argv[3]), ROOT / ".cache" / "extension-wheels" / "all")
