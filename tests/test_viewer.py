"""The web viewer (viewer/) in a real browser against Blender: the Cornell box baked, exported with
`export-gltf`, shown by headless Chromium (SwiftShader WebGL) through the MOZ_lightmap plugin, and
rendered by Blender from the same lightmaps (Apply: base colour × lightmap as emission) from the
glTF's camera. The two must agree region by region, and the page's console must stay clean.

With DETP_BAKE_WRITE_SCREENSHOT=1 the bake is finer and the page's screenshot at exposure 0 is
written to docs/images/viewer_cornell.png (the README's)."""
import functools
import json
import math
import os
import shutil
import struct
import subprocess
import sys
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest

from conftest import CORNELL, ROOT
from detp_bake.cli import main

CHROMIUM = Path("/usr/bin/chromium")
SHOT = ROOT / "tests" / "viewer_shot.mjs"
README_SHOT = ROOT / "docs" / "images" / "viewer_cornell.png"
SIZE = 160  # pixels, square: the Cornell box's camera is square (glTF aspectRatio 1)
# Both sides darkened alike (Blender's Exposure, the viewer's ?exposure=) so no region clips at 8 bits.
EXPOSURE = -1.5
# Regions inside single faces, as (x0, y0, x1, y1) shares of the image, y down.
REGIONS = {
    "back wall": (0.55, 0.22, 0.75, 0.42),
    "left wall": (0.04, 0.20, 0.16, 0.70),
    "right wall": (0.84, 0.20, 0.95, 0.70),
    "floor": (0.20, 0.89, 0.45, 0.96),
    "short box": (0.54, 0.70, 0.70, 0.86),
    "ceiling": (0.30, 0.05, 0.70, 0.15),
}
TOLERANCE = 0.02  # of the region's brightest channel


def _browser_missing():
    """Why the browser half cannot run here, or None."""
    missing = []
    if not CHROMIUM.exists():
        missing.append(f"{CHROMIUM}")
    if shutil.which("node") is None:
        missing.append("node")
    if not (ROOT / "viewer" / "node_modules" / "playwright-core").is_dir() or \
            not (ROOT / "viewer" / "node_modules" / "three").is_dir():
        missing.append("viewer/node_modules")
    if missing:
        return f"needs a browser: {', '.join(missing)} missing (make viewer-node chromium)"
    return None


class _Server:
    """The repository on a free local port, and the test's folder under /model/."""

    def __init__(self, models: Path):
        class Handler(SimpleHTTPRequestHandler):
            def translate_path(self, path):
                if path.startswith("/model/"):
                    return str(models / path[len("/model/"):].split("?")[0])
                return super().translate_path(path)

            def log_message(self, *args):
                pass
        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(ROOT)))
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    def __enter__(self):
        self.thread.start()
        return f"http://127.0.0.1:{self.httpd.server_address[1]}"

    def __exit__(self, *exc):
        self.httpd.shutdown()
        self.httpd.server_close()


def _export(baked: Path, lightmaps: Path, glb: Path) -> None:
    """`export-gltf` in its own process: a bake and Blender's glTF exporter in one bpy process hang
    at its exit (bpy 4.5, in the wheel's exit handlers), which would hang pytest."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "detp_bake", "export-gltf", str(baked), "--lightmaps", str(lightmaps),
                           "--out", str(glb)], capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]


def _shot(url: str, out: Path, size: int) -> dict:
    proc = subprocess.run(["node", str(SHOT), url, str(out), str(size), str(size), str(CHROMIUM)],
                          capture_output=True, text=True, timeout=150, cwd=ROOT)
    lines = proc.stdout.strip().splitlines()
    assert lines, f"viewer_shot.mjs printed nothing (exit {proc.returncode}): {proc.stderr[-2000:]}"
    return json.loads(lines[-1])


def _glb_json(path: Path) -> dict:
    data = path.read_bytes()
    magic, _, _ = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67, "not a .glb"
    length, kind = struct.unpack_from("<II", data, 12)
    assert kind == 0x4E4F534A
    return json.loads(data[20:20 + length])


def _linear(path: Path) -> np.ndarray:
    """An 8-bit sRGB PNG as linear rgb floats."""
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(str(path))
    assert not buf.has_error, buf.geterror()
    s = np.asarray(buf.get_pixels(oiio.FLOAT))[..., :3].astype(np.float64)
    return np.where(s <= 0.04045, s / 12.92, ((s + 0.055) / 1.055) ** 2.4)


def _region_means(img: np.ndarray) -> dict:
    h, w = img.shape[:2]
    out = {}
    for name, (x0, y0, x1, y1) in REGIONS.items():
        px = img[round(y0 * h):round(y1 * h), round(x0 * w):round(x1 * w)].reshape(-1, 3)
        out[name] = (px.mean(axis=0), px.max())
    return out


def _render_in_blender(bpy, baked: Path, report: dict, out: Path) -> None:
    """What Apply shows, rendered: the lightmap frame's emission (base colour × lightmap) made every
    engine's output, lights off, Cycles (camera rays end on emission; exact up to pixel filtering)."""
    from detp_bake.blender import apply_all
    bpy.ops.wm.open_mainfile(filepath=str(baked))
    scene = bpy.context.scene
    files = {o["name"]: o["files"] for o in report["objects"]}
    apply_all(scene, files, None, report["estimator"]["name"])  # report.json: {"name": …, counters}
    for mat in bpy.data.materials:
        nodes = mat.node_tree.nodes if mat.node_tree else None
        frame = nodes.get("detp_bake lightmap") if nodes else None
        if frame is None:
            continue
        for node in [n for n in nodes if n.type == "OUTPUT_MATERIAL"]:
            if node.parent == frame:
                node.target = "ALL"
                node.is_active_output = True
            else:
                nodes.remove(node)
    for obj in scene.objects:
        if obj.type == "LIGHT":
            obj.hide_render = True
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.display_settings.display_device = "sRGB"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = EXPOSURE
    scene.view_settings.gamma = 1.0
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    scene.render.image_settings.color_depth = "8"
    scene.render.filepath = str(out)
    bpy.ops.render.render(write_still=True)


def _vertical_fov(scene) -> float:
    """The vertical field of view Blender renders with (automatic sensor fit: the sensor's width
    spans the image's longer side)."""
    cam, r = scene.camera.data, scene.render
    assert cam.sensor_fit == "AUTO" and cam.type == "PERSP"
    half = math.atan(cam.sensor_width / 2 / cam.lens)
    aspect = r.resolution_x * r.pixel_aspect_x / (r.resolution_y * r.pixel_aspect_y)
    return 2 * (half if aspect <= 1 else math.atan(math.tan(half) / aspect))


def test_viewer_shows_what_blender_renders(tmp_path, bpy):
    why = _browser_missing()
    if why:
        pytest.skip(why)
    readme = os.environ.get("DETP_BAKE_WRITE_SCREENSHOT") == "1"
    lightmaps, baked, glb = tmp_path / "lightmaps", tmp_path / "baked.blend", tmp_path / "cornell.glb"
    quality = ["--photons", "2000000", "--resolution", "128"] if readme else ["--photons", "200000", "--resolution", "64"]
    assert main(["bake", str(CORNELL), "--out", str(lightmaps), *quality, "--save", str(baked)]) == 0
    _export(baked, lightmaps, glb)
    report = json.loads((lightmaps / "report.json").read_text())

    # The view the page takes is the glTF's camera, which is the scene's.
    gltf = _glb_json(glb)
    assert gltf.get("cameras"), "the .glb has no camera: export-gltf must write the scene's (export_cameras=True)"
    lit = [m for m in gltf["materials"] if "MOZ_lightmap" in m.get("extensions", {})]
    assert len(lit) >= len(report["objects"])

    blender_png = tmp_path / "blender.png"
    _render_in_blender(bpy, baked, report, blender_png)
    assert math.isclose(gltf["cameras"][0]["perspective"]["yfov"], _vertical_fov(bpy.context.scene), rel_tol=1e-5)

    web_png = tmp_path / "web.png"
    with _Server(tmp_path) as base:
        page = f"{base}/viewer/index.html?model=/model/{glb.name}&exposure={EXPOSURE}&shot=1"
        result = _shot(page, web_png, SIZE)
        if readme:
            extra = _shot(f"{base}/viewer/index.html?model=/model/{glb.name}&shot=1", tmp_path / "readme.png", 400)
            assert extra["ready"] and not extra["errors"], extra
            README_SHOT.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(tmp_path / "readme.png", README_SHOT)

    assert result["ready"], result
    assert not result["errors"], result["errors"]
    noisy = [m for m in result["console"] if m["type"] in ("error", "warning")]
    assert not noisy, noisy
    assert result["info"]["lightmapped"] == len(report["objects"]) and result["info"]["camera"] == "gltf", result["info"]

    web, blender = _region_means(_linear(web_png)), _region_means(_linear(blender_png))
    for name in REGIONS:
        (w, _), (b, peak) = web[name], blender[name]
        assert peak < 0.99, f"{name}: Blender's render clips there (the test would compare nothing)"
        diff = np.abs(w - b) / b.max()
        assert diff.max() < TOLERANCE, f"{name}: viewer {w.round(4)}, Blender {b.round(4)} ({diff.max():.1%} apart)"


def test_make_viewers_server_serves_the_viewer_and_the_model_only(tmp_path):
    """viewer/serve.py (what `make viewer` runs): the page, its three.js module and the one model
    are there; the repository's .git/config, other files, folders and a way out by '..' are 404."""
    import urllib.error
    import urllib.request
    sys.path.insert(0, str(ROOT / "viewer"))
    try:
        import serve
    finally:
        sys.path.pop(0)
    model = tmp_path / "scene.glb"
    model.write_bytes(b"glTF model bytes")
    (tmp_path / "secret.txt").write_text("not served")
    httpd = serve.server(0, str(model))
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{httpd.server_address[1]}"

    def status(path):
        try:
            with urllib.request.urlopen(base + path, timeout=10) as reply:
                return reply.status, reply.read()
        except urllib.error.HTTPError as exc:
            return exc.code, b""
    try:
        code, page = status("/viewer/index.html")
        assert code == 200 and b"importmap" in page
        assert status("/model/scene.glb") == (200, b"glTF model bytes")
        if (ROOT / "viewer" / "node_modules" / "three").is_dir():
            assert status("/viewer/node_modules/three/build/three.module.js")[0] == 200
        for path in ("/.git/config", "/viewer/../.git/config", "/viewer/%2e%2e/.git/config", "/README.md",
                     "/viewer/", "/viewer/serve.py", "/viewer/package.json", "/model/secret.txt", "/model/",
                     "/viewer/node_modules/three/package.json", "/viewer/node_modules/three/build/../package.json",
                     "/sample_scenes/cornell_box.blend", "/"):
            assert status(path)[0] == 404, path
    finally:
        httpd.shutdown()
        httpd.server_close()
