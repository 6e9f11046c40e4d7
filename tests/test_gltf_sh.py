"""DETP_lightmap_sh (docs/gltf.md, docs/viewer.md): a `--directional sh` Cornell box bake exported
with its L1 maps as L1/L0 ratios in 8 bits, read back against the EXRs, validated by Khronos' validator,
and shown by the viewer: with the vertex normal for both normals, shade() gives L0 back, so the SH
page must look like the same bake exported plain. The ratio encoding itself needs no Blender."""
import json
import shutil
import subprocess

import numpy as np
import pytest

from conftest import CORNELL, ROOT
from detp_bake.lightmap import encoding
from test_gltf import VALIDATOR, _cli, _oiio_read, _primitives, read_glb, view_bytes

SH = "DETP_lightmap_sh"
STEP = 1 / 255  # half of the 8-bit ratio's step of 2/255


def test_ratio_round_trip_is_within_half_a_step_of_the_clamped_ratio():
    rng = np.random.default_rng(3)
    l0 = np.exp(rng.normal(0.0, 3.0, (100_000, 3))) * rng.integers(0, 2, (100_000, 3))
    l1 = l0 * rng.uniform(-1.3, 1.3, (100_000, 3))
    l1[:3] = [[np.nan, 0, 0], [0, 0, 0], [5, -5, 0]]
    back = encoding.ratio_decode(encoding.ratio_encode(l0, l1))
    expected = np.clip(np.where(l0 > 0, np.nan_to_num(l1) / np.where(l0 > 0, l0, 1), 0), -1, 1)
    assert np.abs(back - expected).max() <= STEP * (1 + 1e-5)
    assert encoding.ratio_encode(np.ones(3), np.array([-1.0, 0.0, 1.0])).tolist() == [0, 128, 255]


def test_rgb_png_reads_back_as_written(tmp_path):
    pixels = np.arange(7 * 5 * 3, dtype=np.uint8).reshape(7, 5, 3)
    (tmp_path / "x.png").write_bytes(encoding.png_bytes(pixels))
    assert np.array_equal(_oiio_read(tmp_path / "x.png", unassociated=True)[..., :3], pixels)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The SH bake with --gltf, and the same lightmaps exported plain: report.json without the L1
    files (the folder copied), so the two .glb differ only by DETP_lightmap_sh."""
    tmp = tmp_path_factory.mktemp("gltf_sh")
    out, blend = tmp / "out", tmp / "baked.blend"
    _cli("bake", str(CORNELL), "--directional", "sh", "--photons", "100000", "--resolution", "32",
         "--out", str(out), "--save", str(blend), "--gltf", str(tmp / "sh.glb"))
    plain = tmp / "plain_out"
    shutil.copytree(out, plain)
    report = json.loads((plain / "report.json").read_text())
    for entry in report["objects"]:
        entry["files"] = [f for f in entry["files"] if ".L1" not in f]
    (plain / "report.json").write_text(json.dumps(report))
    _cli("export-gltf", str(blend), "--lightmaps", str(plain), "--out", str(tmp / "plain.glb"))
    files = {o["name"]: o["files"] for o in json.loads((out / "report.json").read_text())["objects"]}
    return {"tmp": tmp, "files": files}


def _exr(files, suffix):
    return _oiio_read(next(f for f in files if f.endswith(f".texel_histogram.{suffix}exr")))[..., :3]


@pytest.mark.blender
def test_every_material_carries_the_l1_ratios_of_its_exrs(exported, tmp_path):
    doc, binary = read_glb(exported["tmp"] / "sh.glb")
    assert SH in doc["extensionsUsed"] and SH not in doc.get("extensionsRequired", [])
    seen = set()
    for name, prim in _primitives(doc):
        ext = doc["materials"][prim["material"]]["extensions"][SH]
        assert {k: ext[k] for k in ("texCoord", "encoding", "space")} == \
            {"texCoord": 1, "encoding": "L1/L0 8-bit", "space": "world glTF (y up)"}
        assert len(ext["l1"]) == 3
        files = exported["files"][name]
        l0 = _exr(files, "")
        x, y, z = (_exr(files, f"L1{a}.") for a in "xyz")
        for index, l1 in zip(ext["l1"], (x, z, -y)):  # glTF (x, y, z) = Blender (x, z, -y)
            image = doc["images"][doc["textures"][index]["source"]]
            (tmp_path / "r.png").write_bytes(view_bytes(doc, binary, image["bufferView"]))
            ratio = encoding.ratio_decode(_oiio_read(tmp_path / "r.png", unassociated=True)[..., :3])
            lit = l0 > 0
            expected = np.clip(np.where(lit, l1 / np.where(lit, l0, 1), 0), -1, 1)
            assert ratio.shape == l0.shape, name
            assert np.abs(ratio - expected).max() <= STEP + 1e-6, name
        seen.add(name)
    assert seen == set(exported["files"])
    plain, _ = read_glb(exported["tmp"] / "plain.glb")
    assert SH not in plain["extensionsUsed"] and len(plain["images"]) * 4 == len(doc["images"])
    assert not [m for m in plain["materials"] if SH in m.get("extensions", {})]


@pytest.mark.blender
def test_the_khronos_validator_finds_no_error(exported):
    node = shutil.which("node")
    if node is None or not VALIDATOR.is_dir():
        pytest.skip("needs node and viewer/node_modules/gltf-validator (npm ci --prefix viewer)")
    proc = subprocess.run([node, str(ROOT / "tests" / "gltf_validate.mjs"), str(exported["tmp"] / "sh.glb")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    issues = json.loads(proc.stdout)["issues"]
    assert issues["numErrors"] == 0, [m for m in issues["messages"] if m["severity"] == 0]


@pytest.mark.blender
def test_the_viewer_shades_sh_like_the_plain_lightmap_with_the_vertex_normal(exported):
    from test_viewer import EXPOSURE, REGIONS, SIZE, _browser_missing, _linear, _region_means, _Server, _shot
    why = _browser_missing()
    if why:
        pytest.skip(why)
    tmp = exported["tmp"]
    shots = {}
    with _Server(tmp) as base:
        for kind in ("plain", "sh"):
            result = _shot(f"{base}/viewer/index.html?model=/model/{kind}.glb&exposure={EXPOSURE}&shot=1",
                           tmp / f"{kind}.png", SIZE)
            assert result["ready"] and not result["errors"], result
            assert not [m for m in result["console"] if m["type"] in ("error", "warning")], result["console"]
            assert result["info"]["lightmapped"] == len(exported["files"]), result["info"]
            assert result["info"]["sh"] == (len(exported["files"]) if kind == "sh" else 0), result["info"]
            shots[kind] = _region_means(_linear(tmp / f"{kind}.png"))
    for name in REGIONS:
        (p, peak), (s, _) = shots["plain"][name], shots["sh"][name]
        assert peak < 0.99, name
        diff = np.abs(s - p) / p.max()
        assert diff.max() < 0.01, f"{name}: SH {s.round(4)}, plain {p.round(4)} ({diff.max():.2%} apart)"
