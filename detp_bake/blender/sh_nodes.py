"""Directional lightmaps in EEVEE: the node groups that evaluate lightmap/sh.py's `shade` against a
material's shading normal, so a normal map is lit from the side the light came from.

Groups made once per file and tagged as ours: "detp_bake SH channel" is `sh.shade` for one colour
channel (L0 a float, L1 a vector), node for node the numpy formula; "detp_bake SH" splits the L0
and per-axis L1 colours into channels, runs the channel group on each and joins them; "detp_bake
dominant" does the same with each channel's L1 rebuilt from a dominant-direction map
(`sh.from_dominant`: the direction times L0 times the directionality).
"detp_bake SH L2" is a light probe's `sh9.irradiance` (nine radiance colours in, E/π out) for
probe-lit objects (probe_light.py).
Normals are world space, as L1 is (Geometry › Normal and a Normal Map node's output both are).
Revert removes a group when nothing uses it any more (`remove_unused`)."""
from __future__ import annotations

import bpy
import numpy as np

from ..lightmap import sh
from ..probes import sh9

GROUP = "detp_bake SH"
DOMINANT_GROUP = "detp_bake dominant"
CHANNEL_GROUP = "detp_bake SH channel"
PROBE_GROUP = "detp_bake SH L2"
TAG = "detp_bake_sh"  # custom property: a group this module made (its formula's version)
VERSION = 1


def _put(nt, sock, value) -> None:
    """Link `value` (a socket) into `sock`, or set it as a constant."""
    if isinstance(value, bpy.types.NodeSocket):
        nt.links.new(value, sock)
    else:
        sock.default_value = value


def _math(nt, op, a, b=0.0, c=None, clamp=False):
    node = nt.nodes.new("ShaderNodeMath")
    node.operation = op
    node.use_clamp = clamp
    for sock, value in zip(node.inputs, (a, b, c)):
        if value is not None:
            _put(nt, sock, value)
    return node.outputs[0]


def _vmath(nt, op, a, b=None, scale=None):
    node = nt.nodes.new("ShaderNodeVectorMath")
    node.operation = op
    _put(nt, node.inputs[0], a)
    if b is not None:
        _put(nt, node.inputs[1], b)
    if scale is not None:
        _put(nt, node.inputs[3], scale)  # the Scale input of SCALE
    return node.outputs["Value" if op == "DOT_PRODUCT" else "Vector"]


def _new_group(name: str, inputs, outputs):
    ng = bpy.data.node_groups.new(name, "ShaderNodeTree")
    for sock_name, kind in inputs:
        ng.interface.new_socket(sock_name, in_out="INPUT", socket_type=kind)
    for sock_name, kind in outputs:
        ng.interface.new_socket(sock_name, in_out="OUTPUT", socket_type=kind)
    ng[TAG] = VERSION
    return ng, ng.nodes.new("NodeGroupInput").outputs, ng.nodes.new("NodeGroupOutput").inputs


def _channel_group():
    """sh.shade for one channel: L0·(a·max(n'·d, 0)/max(n·d, MIN_COS) + (1 − a)·(1 + n'·n)/2)."""
    ng, i, o = _new_group(CHANNEL_GROUP, [("L0", "NodeSocketFloat"), ("L1", "NodeSocketVector"),
                                          ("Normal", "NodeSocketVector"), ("Shading", "NodeSocketVector")],
                          [("Value", "NodeSocketFloat")])
    h = sh.HEMISPHERE_RATIO
    qa = h * h - 1.0
    r = _vmath(ng, "SCALE", i["L1"], scale=_math(ng, "DIVIDE", 1.0, i["L0"]))  # Blender's divide: 0 by 0
    rn, rr = _vmath(ng, "DOT_PRODUCT", r, i["Normal"]), _vmath(ng, "DOT_PRODUCT", r, r)
    qb = _math(ng, "MULTIPLY_ADD", rn, 2.0 * h, -2.0 * h * h)
    qc = _math(ng, "ADD", _math(ng, "MULTIPLY_ADD", rn, -2.0 * h, rr), h * h)
    disc = _math(ng, "MULTIPLY_ADD", qc, -4.0 * qa, _math(ng, "MULTIPLY", qb, qb))
    disc = _math(ng, "SQRT", _math(ng, "MAXIMUM", disc, 0.0))
    a = _math(ng, "MULTIPLY", _math(ng, "ADD", qb, disc), -0.5 / qa, clamp=True)  # (−qb − disc)/(2 qa)
    d = _vmath(ng, "SUBTRACT", r, _vmath(ng, "SCALE", i["Normal"], scale=_math(ng, "MULTIPLY_ADD", a, -h, h)))
    d = _vmath(ng, "NORMALIZE", d)
    towards = _math(ng, "DIVIDE", _math(ng, "MAXIMUM", _vmath(ng, "DOT_PRODUCT", i["Shading"], d), 0.0),
                    _math(ng, "MAXIMUM", _vmath(ng, "DOT_PRODUCT", i["Normal"], d), sh.MIN_COS))
    sky = _math(ng, "MULTIPLY_ADD", _vmath(ng, "DOT_PRODUCT", i["Shading"], i["Normal"]), 0.5, 0.5)
    mix = _math(ng, "MULTIPLY_ADD", a, _math(ng, "SUBTRACT", towards, sky), sky)
    ng.links.new(_math(ng, "MULTIPLY", i["L0"], mix), o["Value"])
    return ng


def _sh_group():
    """L0 and L1x, L1y, L1z colours → the shaded colour, a channel group per colour channel."""
    ng, i, o = _new_group(GROUP, [("L0", "NodeSocketColor"), ("L1x", "NodeSocketColor"),
                                  ("L1y", "NodeSocketColor"), ("L1z", "NodeSocketColor"),
                                  ("Normal", "NodeSocketVector"), ("Shading", "NodeSocketVector")],
                          [("Color", "NodeSocketColor")])
    channel = _group(CHANNEL_GROUP, _channel_group)
    split = {}
    for name in ("L0", "L1x", "L1y", "L1z"):
        node = ng.nodes.new("ShaderNodeSeparateColor")
        ng.links.new(i[name], node.inputs[0])
        split[name] = node.outputs
    join = ng.nodes.new("ShaderNodeCombineColor")
    for c in range(3):
        vec = ng.nodes.new("ShaderNodeCombineXYZ")
        for a, axis in enumerate(("L1x", "L1y", "L1z")):
            ng.links.new(split[axis][c], vec.inputs[a])
        node = ng.nodes.new("ShaderNodeGroup")
        node.node_tree = channel
        ng.links.new(split["L0"][c], node.inputs["L0"])
        ng.links.new(vec.outputs[0], node.inputs["L1"])
        ng.links.new(i["Normal"], node.inputs["Normal"])
        ng.links.new(i["Shading"], node.inputs["Shading"])
        ng.links.new(node.outputs[0], join.inputs[c])
    ng.links.new(join.outputs[0], o["Color"])
    return ng


def _dominant_group():
    """L0, the dominant direction (a colour: x, y, z) and its directionality → the shaded colour."""
    ng, i, o = _new_group(DOMINANT_GROUP, [("L0", "NodeSocketColor"), ("Direction", "NodeSocketColor"),
                                           ("Directionality", "NodeSocketFloat"), ("Normal", "NodeSocketVector"),
                                           ("Shading", "NodeSocketVector")], [("Color", "NodeSocketColor")])
    channel = _group(CHANNEL_GROUP, _channel_group)
    split = ng.nodes.new("ShaderNodeSeparateColor")
    ng.links.new(i["L0"], split.inputs[0])
    join = ng.nodes.new("ShaderNodeCombineColor")
    for c in range(3):
        node = ng.nodes.new("ShaderNodeGroup")
        node.node_tree = channel
        l1 = _vmath(ng, "SCALE", i["Direction"], scale=_math(ng, "MULTIPLY", split.outputs[c], i["Directionality"]))
        ng.links.new(split.outputs[c], node.inputs["L0"])
        ng.links.new(l1, node.inputs["L1"])
        ng.links.new(i["Normal"], node.inputs["Normal"])
        ng.links.new(i["Shading"], node.inputs["Shading"])
        ng.links.new(node.outputs[0], join.inputs[c])
    ng.links.new(join.outputs[0], o["Color"])
    return ng


def _probe_group():
    """A probe's SH L2 (nine radiance colours C0 … C8, probes/sh9.py) → E(n)/π at world normal n:
    Σ_k (A_l/π) Y_k(n) C_k, sh9.irradiance node for node."""
    ng, i, o = _new_group(PROBE_GROUP, [("Normal", "NodeSocketVector")] +
                          [(f"C{k}", "NodeSocketColor") for k in range(sh9.COEFFICIENTS)],
                          [("Color", "NodeSocketColor")])
    split = ng.nodes.new("ShaderNodeSeparateXYZ")
    ng.links.new(i["Normal"], split.inputs[0])
    x, y, z = split.outputs
    polynomial = (1.0, y, z, x, _math(ng, "MULTIPLY", x, y), _math(ng, "MULTIPLY", y, z),
                  _math(ng, "MULTIPLY_ADD", _math(ng, "MULTIPLY", z, z), 3.0, -1.0),
                  _math(ng, "MULTIPLY", x, z),
                  _math(ng, "SUBTRACT", _math(ng, "MULTIPLY", x, x), _math(ng, "MULTIPLY", y, y)))
    # Y_k(n) = constant_k · polynomial_k(n): the constants read off sh9.basis at a direction where
    # no polynomial is 0.
    d = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    x_, y_, z_ = d
    at = sh9.basis(d) / np.array([1.0, y_, z_, x_, x_ * y_, y_ * z_, 3 * z_ * z_ - 1, x_ * z_, x_ * x_ - y_ * y_])
    total = None
    for k, term in enumerate(polynomial):
        factor = float(sh9.COSINE_OVER_PI[k] * at[k])
        scale = _math(ng, "MULTIPLY", term, factor) if k else factor
        term_colour = _vmath(ng, "SCALE", i[f"C{k}"], scale=scale)
        total = term_colour if total is None else _vmath(ng, "ADD", total, term_colour)
    ng.links.new(total, o["Color"])
    return ng


def probe_group():
    """The probe SH group, made once per file."""
    return _group(PROBE_GROUP, _probe_group)


def _group(name: str, make):
    """Our group of that name (this version), made when missing."""
    for ng in bpy.data.node_groups:
        if ng.name.split(".")[0] == name and ng.get(TAG) == VERSION:
            return ng
    return make()


def wire(nt, frame, l0_socket, l1_images: dict, uv_socket, shading, x: float):
    """Add to material tree `nt` (under `frame`) the directional textures (`l1_images`: {L1x, L1y,
    L1z: image}, or {"dir": the dominant map}) and their group, fed by the lightmap's colour
    `l0_socket` and the shading normal `shading` (a socket, None: the surface's own normal);
    returns the group's colour output."""
    geometry = nt.nodes.new("ShaderNodeNewGeometry")
    group = nt.nodes.new("ShaderNodeGroup")
    dominant = "dir" in l1_images
    group.node_tree = _group(DOMINANT_GROUP, _dominant_group) if dominant else _group(GROUP, _sh_group)
    group.label = "Directional lightmap (" + ("dominant direction)" if dominant else "SH L1)")
    nt.links.new(l0_socket, group.inputs["L0"])
    for k, (axis, image) in enumerate(l1_images.items()):
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image, tex.interpolation = image, "Linear"
        tex.parent, tex.location = frame, (x, -700.0 - 280.0 * k)
        nt.links.new(uv_socket, tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], group.inputs["Direction" if dominant else axis])
        if dominant:
            nt.links.new(tex.outputs["Alpha"], group.inputs["Directionality"])
    nt.links.new(geometry.outputs["Normal"], group.inputs["Normal"])
    nt.links.new(shading if shading is not None else geometry.outputs["Normal"], group.inputs["Shading"])
    geometry.parent, geometry.location = frame, (x, -1540.0)
    group.parent, group.location = frame, (x + 250.0, -700.0)
    return group.outputs["Color"]


def remove_unused() -> None:
    """Remove our groups nothing uses any more (the SH group first: it uses the channel group)."""
    for name in (GROUP, DOMINANT_GROUP, CHANNEL_GROUP, PROBE_GROUP):
        for ng in [g for g in bpy.data.node_groups if g.name.split(".")[0] == name and TAG in g]:
            if ng.users == 0:
                bpy.data.node_groups.remove(ng)
