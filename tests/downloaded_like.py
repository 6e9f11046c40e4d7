"""A scene shaped like a downloaded one, made with bpy (run in the test's Blender or as
`python tests/downloaded_like.py OUT.blend`): what real files hold and hand-made test scenes lack.

- Room: one mesh, seven material slots, two of them (floor, wood) used by no face.
- CrateA, CrateB: two objects sharing one material, Shared.
- Glow: an Emission shader, no Principled BSDF; Bust: a material whose surface is a node group.
- Statue: exported but not baked (the tests bake the others by name).
- Town: a block of 16 boxes, their faces cut in 3×3 quads, joined into one mesh of 864 quads with
  render UVs and no lightmap UV layer, so the bake has to make one.
"""
import sys

import bpy  # first: bmesh is a module of Blender's
import bmesh

SLOTS = ("walls", "ceiling", "floor", "trim", "glass", "wood", "rug")
UNUSED = ("floor", "wood")
BAKED = ("Room", "CrateA", "CrateB", "Glow", "Bust", "Town")


def _principled(name, colour):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None or bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    node = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    node.inputs["Base Color"].default_value = (*colour, 1.0)
    return mat


def _surface(name, kind):
    """A material whose output is fed by an Emission shader or by a node group (no Principled)."""
    mat = _principled(name, (0.5, 0.5, 0.5))
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.remove(next(n for n in nodes if n.type == "BSDF_PRINCIPLED"))
    out = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    if kind == "emission":
        node = nodes.new("ShaderNodeEmission")
        node.inputs["Strength"].default_value = 0.5
        links.new(node.outputs[0], out.inputs["Surface"])
        return mat
    group = bpy.data.node_groups.new("Plaster", "ShaderNodeTree")
    group.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    inner = group.nodes.new("ShaderNodeBsdfDiffuse")
    group_out = group.nodes.new("NodeGroupOutput")
    group.links.new(inner.outputs[0], group_out.inputs[0])
    node = nodes.new("ShaderNodeGroup")
    node.node_tree = group
    links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def _box(bm, lo, hi):
    verts = [bm.verts.new((x, y, z)) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    for f in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
        bm.faces.new([verts[i] for i in f])


def _object(name, build, materials, uv=True):
    bm = bmesh.new()
    build(bm)
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces)
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    if uv:
        me.uv_layers.new(name="UVMap")
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    for mat in materials:
        me.materials.append(mat)
    return obj


def build() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    slots = [_principled(n, (0.3 + 0.08 * i, 0.6, 0.5)) for i, n in enumerate(SLOTS)]
    room = _object("Room", lambda bm: _box(bm, (-4, -4, 0), (4, 4, 3)), slots)
    used = [i for i, n in enumerate(SLOTS) if n not in UNUSED]
    for face, index in zip(room.data.polygons, [0, 0, 1, 3, 4, 6]):
        face.material_index = index
    room.data.flip_normals()
    assert sorted({f.material_index for f in room.data.polygons}) == used
    shared = _principled("Shared", (0.7, 0.5, 0.3))
    _object("CrateA", lambda bm: _box(bm, (-3, -3, 0), (-2, -2, 1)), [shared])
    _object("CrateB", lambda bm: _box(bm, (2, -3, 0), (3, -2, 1)), [shared])
    _object("Glow", lambda bm: _box(bm, (-3, 2, 0), (-2.5, 3, 2)), [_surface("Neon", "emission")])
    _object("Bust", lambda bm: _box(bm, (2.5, 2, 0), (3, 3, 1.5)), [_surface("Plaster", "group")])
    _object("Statue", lambda bm: _box(bm, (0, 2.5, 0), (0.5, 3, 1.2)), [shared])

    def town(bm):  # facades cut in 3×3 quads, as a game level's walls are
        for i in range(4):
            for j in range(4):
                x, y = -1.5 + 0.8 * i, -1.5 + 0.8 * j
                _box(bm, (x, y, 0.01), (x + 0.6, y + 0.6, 0.4 + 0.2 * ((i * 7 + j * 3) % 5)))
        bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=2, use_grid_fill=True)
    _object("Town", town, [_principled("Brick", (0.6, 0.4, 0.3))])
    light = bpy.data.lights.new("Lamp", "POINT")
    light.energy = 800.0
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = (0.0, 0.0, 2.5)
    scene.collection.objects.link(lamp)
    scene.render.engine = "CYCLES"


if __name__ == "__main__":
    build()
    bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1])
