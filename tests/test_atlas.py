"""Atlases: packing (every object inside its atlas, no texel shared, one texel density) and a bake
into atlases that agrees with one lightmap per object."""
import json

import numpy as np
import pytest

from detp_bake.errors import BakeError
from detp_bake.lightmap import atlas, texels as texels_mod
from detp_bake.scene import AreaLight, BakeObject, PointLight, Scene


def box(size, at=(0.0, 0.0, 0.0)):
    """A box's 12 triangles in world space, and UVs with each face its own island."""
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * size + at
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris, uvs = [], []
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    for f, (a, b, c, d) in enumerate(faces):
        tris += [corners[[a, b, c]], corners[[a, c, d]]]
        island = 0.02 + square * 0.14 + [0.16 * (f % 3), 0.16 * (f // 3)]
        uvs += [island[[0, 1, 2]], island[[0, 2, 3]]]
    return np.array(tris), np.array(uvs)


def meshes(sizes, keep=True):
    out = []
    for i, s in enumerate(sizes):
        p, uv = box(s, (3.0 * i, 0.0, 0.0))
        out.append(atlas.Mesh(f"box{i}", p, uv if keep else None))
    return out


def rasterised(packing, meshes_):
    """Each object's covered pixels in its atlas, by the bake's own (conservative) rasteriser."""
    tris = np.concatenate([m.positions for m in meshes_])
    uvs = np.concatenate([packing.objects[m.name].uvs for m in meshes_]).astype(np.float32)
    objs, first = [], 0
    for m in meshes_:
        placed = packing.objects[m.name]
        objs.append(BakeObject(m.name, first, len(m.positions), packing.sizes[placed.atlas], True))
        first += len(m.positions)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    scene = Scene(positions=tris, normals=np.repeat(n[:, None], 3, axis=1), uvs=uvs,
                  albedo=np.full((len(tris), 3), 0.5), emission=np.zeros((len(tris), 3)), objects=objs,
                  lights=[PointLight("L", np.zeros(3), np.ones(3))], world=np.zeros(3))
    ts = texels_mod.rasterise(scene)
    return {lm.name: (packing.objects[lm.name].atlas, set(ts.pixel[lm.texels].tolist())) for lm in ts.lightmaps}


@pytest.mark.parametrize("keep", [True, False])
def test_objects_pack_apart_inside_their_atlas_at_one_density(keep):
    sizes = [2.0, 1.5, 1.0, 1.0, 0.8, 0.6, 3.0, 0.5]  # 1.0 twice: duplicates get charts of their own
    ms = meshes(sizes, keep)
    packing = atlas.pack(ms, density=16.0, size=160, padding=2, keep=keep)
    assert packing.count >= 2 and not packing.warnings  # they do not fit one 160² atlas together
    for m in ms:
        placed = packing.objects[m.name]
        side = packing.sizes[placed.atlas]
        assert side <= 160 and side % 4 == 0
        texel = placed.uvs * side
        assert texel.min() >= 0.5 - 1e-3 and texel.max() <= side - 0.5 + 1e-3  # inside, on texel centres
        assert placed.density == pytest.approx(16.0, rel=0.1), m.name
    covered = rasterised(packing, ms)
    names = list(covered)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if covered[a][0] == covered[b][0]:
                assert not covered[a][1] & covered[b][1], (a, b)


def test_an_object_too_big_for_an_atlas_gets_a_lower_density_and_a_warning():
    packing = atlas.pack(meshes([4.0]), density=64.0, size=64, padding=2)
    assert packing.count == 1
    assert packing.objects["box0"].density < 0.9 * 64.0
    assert "too big for one 64x64 atlas" in packing.warnings[0]


def test_bad_packing_input_is_refused_by_name():
    with pytest.raises(BakeError, match="texel_density"):
        atlas.pack(meshes([1.0]), density=0.0, size=64)
    flat = atlas.Mesh("Flat", np.zeros((2, 3, 3)))
    with pytest.raises(BakeError, match="'Flat'"):
        atlas.pack([flat], density=8.0, size=64)


def _object_means(result, scene):
    """Area-weighted mean E/π per object of a bake's texels (before denoising)."""
    owner = scene.object_index()[result.texels.triangle]
    area = result.texels.area.astype(np.float64)
    out = {}
    for i, obj in enumerate(scene.objects):
        mine = owner == i
        if mine.any():
            out[obj.name] = np.average(result.value[mine].mean(axis=1), weights=area[mine])
    return out


def test_an_atlas_bake_of_the_cornell_box_matches_one_lightmap_per_object(cornell, bpy, tmp_path):
    from detp_bake import blender
    from detp_bake.run.bake import BakeSettings, compute
    common = dict(photons=400_000, seed=2, denoise=False, texel_density=12.0)
    per_object = BakeSettings(resolution=64, **common)
    in_atlas = BakeSettings(lightmaps="atlas", atlas_size=256, atlas_charts="smart", **common)
    scene_a = blender.export_scene(cornell, atlas=in_atlas, log=lambda m: None)
    assert {o.image for o in scene_a.objects} == {"atlas_0"}
    a = compute(scene_a, in_atlas)
    assert [lm.name for lm in a.texels.lightmaps] == ["atlas_0"] and len(a.images) == 1
    scene_o = blender.export_scene(cornell, log=lambda m: None)
    o = compute(scene_o, per_object)
    mean_a, mean_o = _object_means(a, scene_a), _object_means(o, scene_o)
    assert set(mean_a) == set(mean_o) == {o.name for o in scene_o.objects}
    for name in mean_o:
        assert mean_a[name] == pytest.approx(mean_o[name], rel=0.03), name
    # report.json: each object in its atlas, where, at the density; the atlas's fill ratio
    report = a.report()
    (entry,) = [e for e in report["objects"] if e["name"] == "Floor"]
    assert entry["image"] == "atlas_0" and entry["texels"] > 0 and len(entry["rect"]) == 4
    assert 1.0 / entry["texel_size"] == pytest.approx(12.0, rel=0.1)
    (info,) = report["atlases"]
    assert info["name"] == "atlas_0" and set(info["objects"]) == set(mean_o) and 0.2 < info["fill"] <= 1.0


def test_cli_atlas_bake_applies_through_the_atlas_layer_and_rebakes_when_an_object_changes(cornell, bpy, tmp_path):
    from detp_bake.cli import main
    out = tmp_path / "out"
    saved = tmp_path / "baked.blend"
    args = ["bake", "--photons", "50000", "--lightmaps", "atlas", "--texel-density", "10", "--atlas-size", "128",
            "--out", str(out), "--apply", "--save", str(saved)]
    assert main(args, bl_scene=cornell) == 0
    assert (out / "atlas_0.texel_histogram.exr").exists() and not (out / "Floor.texel_histogram.exr").exists()
    floor = cornell.objects["Floor"]
    assert "LightmapAtlas" in floor.data.uv_layers and "Lightmap" in floor.data.uv_layers
    nodes = floor.material_slots[0].material.node_tree.nodes
    uv_nodes = [n for n in nodes if n.type == "UVMAP" and n.parent is not None]
    assert uv_nodes and all(n.uv_map == "LightmapAtlas" for n in uv_nodes)
    images = {n.image.name for n in nodes if n.type == "TEX_IMAGE" and n.image is not None and n.parent is not None}
    assert images == {"atlas_0.texel_histogram"}
    # Unchanged: every object reused; one object changed: its atlas, all of it, baked again.
    assert main(args, bl_scene=cornell) == 0
    report = json.loads((out / "report.json").read_text())
    assert all(e["reused"] for e in report["objects"])
    cornell.objects["ShortBox"].data.vertices[0].co.z += 0.05
    assert main(args, bl_scene=cornell) == 0
    report = json.loads((out / "report.json").read_text())
    assert not any(e["reused"] for e in report["objects"])


def test_linked_duplicates_get_meshes_and_texels_of_their_own(cornell, bpy):
    from detp_bake import blender
    from detp_bake.run.bake import BakeSettings
    from detp_bake.lightmap import texels as texels_mod
    box = cornell.objects["ShortBox"]
    twin = box.copy()  # a linked duplicate: the same mesh
    twin.name = "ShortBoxTwin"
    twin.location.x += 2.0
    cornell.collection.objects.link(twin)
    assert twin.data == box.data
    said = []
    settings = BakeSettings(lightmaps="atlas", texel_density=16.0, atlas_size=512)
    scene = blender.export_scene(cornell, atlas=settings, log=said.append)
    assert twin.data != box.data and "LightmapAtlas" in twin.data.uv_layers
    assert any("ShortBoxTwin" in m and "mesh of its own" in m for m in said)
    ts = texels_mod.rasterise(scene)
    (lm,) = ts.lightmaps
    owner = scene.object_index()[ts.triangle]
    mine = {name: set(ts.pixel[owner == scene.objects.index(scene.object_named(name))].tolist())
            for name in ("ShortBox", "ShortBoxTwin")}
    assert len(mine["ShortBox"]) == len(mine["ShortBoxTwin"]) > 50
    # Sharing UVs, the two would lie on the same texels: every texel of theirs under two triangles.
    assert lm.overlap < 0.01
    rects = [lm.placement[n]["rect"] for n in ("ShortBox", "ShortBoxTwin")]
    assert rects[0] != rects[1]


def _two_plates_in_one_atlas(gap_texels: float, res: int = 64):
    """A plate under a square area light (its direct light is soft, so it is denoised) and a plate
    facing away from it (it receives nothing at all), their charts side by side in one atlas
    `gap_texels` apart."""
    def plate(x0, facing_up):
        p = np.array([[[x0, 0, 0], [x0 + 1, 0, 0], [x0 + 1, 1, 0]], [[x0, 0, 0], [x0 + 1, 1, 0], [x0, 1, 0]]], float)
        return p if facing_up else p[:, [0, 2, 1]]
    half = (0.5 - 0.5 * gap_texels / res)
    uv_left = np.array([[[0.02, 0.02], [half, 0.02], [half, 0.98]], [[0.02, 0.02], [half, 0.98], [0.02, 0.98]]])
    uv_right = uv_left + [0.5 + 0.5 * gap_texels / res - 0.02, 0.0]
    lit, dark = plate(0.0, True), plate(3.0, False)
    tris = np.concatenate([lit, dark])
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    objs = [BakeObject("Lit", 0, 2, res, True, image="atlas_0"), BakeObject("Dark", 2, 2, res, True, image="atlas_0")]
    return Scene(positions=tris, normals=np.repeat(n[:, None], 3, axis=1),
                 uvs=np.concatenate([uv_left, uv_right[:, [0, 2, 1]]]).astype(np.float32),
                 albedo=np.zeros((4, 3)), emission=np.zeros((4, 3)), objects=objs,
                 lights=[AreaLight("Panel", np.array([[1, 0, 0, 0.5], [0, 1, 0, 0.5], [0, 0, 1, 1.0], [0, 0, 0, 1.0]]),
                                   "SQUARE", 0.5, 0.5, np.full(3, 100.0))], world=np.zeros(3))


def test_denoising_an_atlas_keeps_one_objects_light_off_its_neighbour():
    from detp_bake.lightmap import denoise
    from detp_bake.run.bake import BakeSettings, compute
    if not denoise.available():
        pytest.skip("pyoidn is not installed")
    r = compute(_two_plates_in_one_atlas(gap_texels=3), BakeSettings(photons=20_000, seed=1, margin=2))
    (lm,) = r.texels.lightmaps
    image, mask = r.images["atlas_0"], r.masks["atlas_0"]
    owner = r.texels.triangle[lm.texels] >= 2  # the dark plate's texels
    dark = np.zeros(mask.shape, bool)
    dark.flat[r.texels.pixel[lm.texels][owner]] = True
    lit_mean = image[mask & ~dark].mean()
    assert lit_mean > 1.0 and image[dark].max() <= 1e-6 * lit_mean


def test_compare_and_frame_ranges_work_on_atlases(cornell, bpy, tmp_path):
    from detp_bake.cli import main
    atlas_args = ["--lightmaps", "atlas", "--texel-density", "8", "--atlas-size", "128", "--photons", "30000"]
    assert main(["compare", "--estimators", "texel_histogram", "disc_index", "--out", str(tmp_path / "cmp"),
                 *atlas_args], bl_scene=cornell) == 0
    for name in ("texel_histogram", "disc_index"):
        assert (tmp_path / "cmp" / f"atlas_0.{name}.exr").exists()
    report = json.loads((tmp_path / "cmp" / "report.json").read_text())
    entries = report["estimators"]["disc_index"]["objects"]
    assert {e["image"] for e in entries} == {"atlas_0"} and len(entries) == 7
    # A range: the hybrid, with the tall box moving between the frames; one atlas per frame.
    tall = cornell.objects["TallBox"]
    tall.keyframe_insert("location", frame=1)
    tall.location.x += 0.3
    tall.keyframe_insert("location", frame=2)
    assert main(["bake", "--frames", "1-2", "--estimator", "hybrid", "--out", str(tmp_path / "frames"),
                 *atlas_args], bl_scene=cornell) == 0
    assert sorted(p.name for p in (tmp_path / "frames").glob("atlas_0.hybrid.*.exr")) == \
        ["atlas_0.hybrid.0001.exr", "atlas_0.hybrid.0002.exr"]


def test_live_preview_and_revert_of_an_atlas_leave_the_materials_as_they_were(cornell, bpy, tmp_path):
    from detp_bake import blender
    from detp_bake.blender.preview import LivePreview
    from detp_bake.run.bake import BakeSettings, compute
    from detp_bake.run.results import preview_images
    from detp_bake.run.writing import write
    settings = BakeSettings(lightmaps="atlas", texel_density=8.0, atlas_size=128, photons=20_000, denoise=False)
    scene = blender.export_scene(cornell, atlas=settings, log=lambda m: None)
    r = compute(scene, settings)
    names = [o.name for o in scene.objects]
    before = {m.name: len(m.node_tree.nodes) for m in bpy.data.materials if m.node_tree}
    preview = LivePreview(cornell, names, None)
    preview.update(preview_images(r.texels, r.value, settings.margin))
    for name in names:  # every object shows the atlas through the atlas layer
        mat = cornell.objects[name].material_slots[0].material
        assert any(n.type == "UVMAP" and n.uv_map == "LightmapAtlas" for n in mat.node_tree.nodes), name
    preview.end()
    assert {m.name: len(m.node_tree.nodes) for m in bpy.data.materials if m.node_tree} == before
    assert not [i for i in bpy.data.images if i.name.startswith("detp_bake preview")]
    write(r, tmp_path)
    blender.apply_all(cornell, r.files, None, settings.estimator)
    assert len([i for i in bpy.data.images if i.name.startswith("atlas_0")]) == 1  # loaded once
    for name in names:
        assert blender.revert(cornell.objects[name])
    assert {m.name: len(m.node_tree.nodes) for m in bpy.data.materials if m.node_tree} == before
    assert not [i for i in bpy.data.images if i.name.startswith("atlas_0")]
