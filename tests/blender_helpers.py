"""Helpers for tests that run the bpy wheel: scene export and node-tree snapshots."""
import numpy as np


def export(bpy, objects=None, uv_layer=None, resolution=32):
    from detp_bake import blender
    scene = bpy.context.scene
    return blender.export_scene(scene, bpy.context.evaluated_depsgraph_get(), objects, uv_layer,
                                      resolution, log=lambda msg: None)


def _value(v):
    try:
        return tuple(round(float(x), 6) for x in v)
    except TypeError:
        return round(float(v), 6) if isinstance(v, (int, float)) else str(v)


def node_tree_snapshot(mat):
    """Everything about a material's node tree that a revert must restore."""
    nt = mat.node_tree
    nodes = []
    for n in nt.nodes:
        inputs = tuple((s.identifier, _value(s.default_value)) for s in n.inputs if hasattr(s, "default_value"))
        nodes.append((n.name, n.bl_idname, tuple(round(c, 3) for c in n.location),
                      getattr(n, "is_active_output", None), n.parent.name if n.parent else None, inputs))
    links = sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name, l.to_socket.identifier)
                   for l in nt.links)
    return sorted(nodes), links, dict(mat.items()) if hasattr(mat, "items") else {}


def scene_snapshot(bpy):
    """Materials, slots, images and UV layers of the open file."""
    mats = {m.name: node_tree_snapshot(m) for m in bpy.data.materials if m.node_tree}
    slots = {o.name: [s.material.name if s.material else None for s in o.material_slots]
             for o in bpy.data.objects}
    uvs = {m.name: [l.name for l in m.uv_layers] for m in bpy.data.meshes}
    # Blender 4.5 stores a registered PointerProperty group ("detp_bake") once it is read:
    # that is the add-on's own settings storage, not a change to the user's data.
    props = {o.name: sorted(k for k in o.keys() if k != "detp_bake") for o in bpy.data.objects}
    return {"materials": mats, "slots": slots, "images": sorted(i.name for i in bpy.data.images),
            "uvs": uvs, "props": props}


def plane_object(bpy, name, size, location, rotation=(0, 0, 0), material=None):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    obj = bpy.context.active_object
    obj.name = name
    if material is not None:
        obj.data.materials.append(material)
    return obj


def principled(bpy, name, base=(0.8, 0.8, 0.8), emission=(0, 0, 0), strength=0.0):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None or bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    node = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    node.inputs["Base Color"].default_value = (*base, 1.0)
    node.inputs["Emission Color"].default_value = (*emission, 1.0)
    node.inputs["Emission Strength"].default_value = strength
    return mat


def lambert(bpy, name, base=(0.8, 0.8, 0.8), emission=(0, 0, 0), strength=0.0):
    """A Principled BSDF without its specular layer (Specular IOR Level 0, roughness 1): Lambertian in
    Cycles, which is what the bake models."""
    mat = principled(bpy, name, base=base, emission=emission, strength=strength)
    node = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    node.inputs["Roughness"].default_value = 1.0
    node.inputs["Specular IOR Level"].default_value = 0.0
    return mat


def sky_world(bpy, scene, colour, strength=1.0):
    """A world of one colour (a Background node) on `scene`."""
    world = bpy.data.worlds.new("Sky")
    scene.world = world
    if world.node_tree is None or bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    bg.inputs["Color"].default_value = (*colour, 1.0)
    bg.inputs["Strength"].default_value = strength
    return world


def relative_rmse(ours, ref, mask):
    a, b = ours[mask], ref[mask]
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(b))
