"""Materials as Cycles shades them, reduced to what lightmaps need: diffuse albedo (a constant times
an optional image), opacity (a constant times an optional image's alpha), emitted radiance.

Part of the Blender adapter (it reads node trees and images; export.py calls it). The graph
is read from the active Cycles output: Principled, Diffuse, Emission, Transparent, and Mix or Add
Shader over them. A colour socket may be a constant, an Image Texture (through a UV Map node or the
render UV map), a Color Attribute, or one of these through Mix/MixRGB (multiply or mix with a
constant), Gamma, Invert, Bright/Contrast, Hue/Saturation/Value or RGB Curves: those colour
operations are applied to the exported copy of the image, so the tracer sees what Cycles sees.
Anything else falls back to the socket's own value, and the material is named once in the log.
"""
from __future__ import annotations

import colorsys
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..transport.textures import EXTENSIONS, INTERPOLATIONS, LINEAR, Textures, srgb_to_linear

DEFAULT_ALBEDO = (0.8, 0.8, 0.8)
MAX_TEXTURE = 1024  # longest side of an exported image: photon bounces need no more


@dataclass(frozen=True)
class ImageUse:
    """An image as one Image Texture node reads it, with the colour operations after it."""
    image: object  # bpy Image
    extension: int
    interpolation: int
    uv: Optional[str]  # UV map name; None: the mesh's render UV map
    ops: tuple = ()  # ("gamma", g), ("invert", f), ...: applied to RGB, in order


@dataclass
class Surface:
    albedo: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_ALBEDO))
    albedo_image: Optional[ImageUse] = None
    colour_attribute: Optional[str] = None  # the albedo also scales by this per-corner colour ("" = active)
    opacity: float = 1.0
    opacity_image: Optional[ImageUse] = None  # its alpha scales the opacity
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    notes: list = field(default_factory=list)


def _rgb(value) -> np.ndarray:
    return np.array([value[0], value[1], value[2]], float) if hasattr(value, "__len__") else np.full(3, float(value))


def _input(node, *names):
    for name in names:
        sock = node.inputs.get(name)
        if sock is not None and getattr(sock, "enabled", True):
            return sock
    # Blender's ShaderNodeMix has several sockets per name; take the enabled one.
    for sock in node.inputs:
        if sock.name in names and getattr(sock, "enabled", True):
            return sock
    return None


def _const(sock, default=0.0) -> float:
    return float(sock.default_value) if sock is not None else default


def linked_socket(sock):
    """(node, output socket) feeding `sock`, through reroutes; None when unlinked."""
    while sock is not None and sock.is_linked:
        link = sock.links[0]
        if not getattr(link, "is_valid", True) or getattr(link, "is_muted", False):
            return None
        node = link.from_node
        if node.type == "REROUTE":
            sock = node.inputs[0]
            continue
        return node, link.from_socket
    return None


def _uv_of(tex_node, notes) -> Optional[str]:
    src = linked_socket(tex_node.inputs.get("Vector"))
    if src is None:
        return None
    node, out = src
    if node.type == "UVMAP":
        return node.uv_map or None
    if node.type == "TEX_COORD" and out.name == "UV":
        return None
    notes.append(f"'{tex_node.name}' reads coordinates from a {node.type.lower()} node: the render UV map is used")
    return None


def image_use(node, notes, ops=(), read_uv: bool = True) -> Optional[ImageUse]:
    img = node.image
    if img is None:
        return None
    if not img.has_data and img.source in ("FILE", "SEQUENCE", "TILED") and not img.packed_file:
        try:
            img.reload()
        except RuntimeError:
            pass
    if img.size[0] == 0 or img.size[1] == 0:
        notes.append(f"image '{img.name}' has no pixels (missing file?): its node's colour is ignored")
        return None
    return ImageUse(img, EXTENSIONS.get(getattr(node, "extension", "REPEAT"), 0),
                    INTERPOLATIONS.get(node.interpolation, LINEAR),
                    _uv_of(node, notes) if read_uv else None, tuple(ops))


_COLOUR_OPS = ("GAMMA", "INVERT", "BRIGHTCONTRAST", "HUE_SAT", "CURVE_RGB")


def colour(sock, notes, ops=()) -> tuple[np.ndarray, Optional[ImageUse], Optional[str]]:
    """What a colour socket carries: (constant RGB factor, image or None, colour attribute or None)."""
    src = linked_socket(sock)
    if src is None:
        return _rgb(sock.default_value) if sock is not None else np.ones(3), None, None
    node, out = src
    if node.type == "TEX_IMAGE":
        use = image_use(node, notes, ops)
        if use is None:
            return (_rgb(sock.default_value) if hasattr(sock, "default_value") else np.ones(3)), None, None
        return np.ones(3), use, None
    if node.type == "RGB":
        return _rgb(out.default_value), None, None
    if node.type == "VERTEX_COLOR" and not ops:
        return np.ones(3), None, node.layer_name or ""
    if node.type in _COLOUR_OPS:
        colour_in = _input(node, "Color")
        op = _colour_op(node, notes)
        if op is not None:
            const, use, attr = colour(colour_in, notes, (op,) + tuple(ops))
            if use is not None:
                return const, use, attr
            return _apply_ops(const[None, :], (op,) + tuple(ops))[0], None, attr
    if node.type in ("MIX_RGB", "MIX") and getattr(node, "data_type", "RGBA") == "RGBA" and not ops:
        return _mix(node, notes)
    notes.append(f"a {node.type.lower()} node feeds a colour: its default value is used")
    return (_rgb(sock.default_value) if hasattr(sock, "default_value") else np.ones(3)), None, None


def _mix(node, notes):
    fac_sock = _input(node, "Factor", "Fac")
    a_sock = _input(node, "A", "Color1")
    b_sock = _input(node, "B", "Color2")
    if linked_socket(fac_sock) is not None:
        notes.append(f"'{node.name}' has a linked factor: its value is used")
    f = min(max(_const(fac_sock, 0.5), 0.0), 1.0)
    ca, ia, va = colour(a_sock, notes)
    cb, ib, vb = colour(b_sock, notes)
    blend = node.blend_type
    textured = (ia or va) is not None, (ib or vb) is not None
    if not any(textured):
        if blend == "MULTIPLY":
            return ca * (1 - f + f * cb), None, None
        if blend != "MIX":
            notes.append(f"'{node.name}' blends by {blend.lower()}: mixed instead")
        return ca * (1 - f) + cb * f, None, None
    if textured[0] and textured[1]:
        notes.append(f"'{node.name}' mixes two textures: the first is used")
        return ca, ia, va
    if blend == "MULTIPLY":
        if textured[0]:
            return ca * (1 - f + f * cb), ia, va  # mix(T, T·c, f) = T·(1 − f + f·c): exact
        if f < 1.0:
            notes.append(f"'{node.name}' multiplies a colour by a texture at factor {f:.2f}: factor 1 used")
        return ca * cb, ib, vb
    notes.append(f"'{node.name}' mixes a texture with a colour: the texture is used, scaled")
    if textured[0]:
        return ca * (1 - f) + cb * f, ia, va
    return ca * (1 - f) + cb * f, ib, vb


def _colour_op(node, notes):
    t = node.type
    if t == "GAMMA":
        return ("gamma", _const(_input(node, "Gamma"), 1.0))
    if t == "INVERT":
        return ("invert", _const(_input(node, "Fac"), 1.0))
    if t == "BRIGHTCONTRAST":
        return ("brightcontrast", _const(_input(node, "Bright"), 0.0), _const(_input(node, "Contrast"), 0.0))
    if t == "HUE_SAT":
        return ("hsv", _const(_input(node, "Hue"), 0.5), _const(_input(node, "Saturation"), 1.0),
                _const(_input(node, "Value"), 1.0), _const(_input(node, "Fac"), 1.0))
    if t == "CURVE_RGB":
        mapping = node.mapping
        mapping.initialize()
        x = np.linspace(0.0, 1.0, 257)
        tables = []
        for c in range(3):
            tables.append(tuple(mapping.evaluate(mapping.curves[3], mapping.evaluate(mapping.curves[c], v))
                                for v in x))
        return ("curves", _const(_input(node, "Fac"), 1.0), tuple(tables))
    return None


def _apply_ops(rgb: np.ndarray, ops) -> np.ndarray:
    """Colour operations on (N, 3) linear RGB, first to last (as the nodes after the image)."""
    out = np.asarray(rgb, np.float64).copy()
    for op in ops:
        kind = op[0]
        if kind == "gamma":
            out = np.where(out > 0.0, np.power(np.maximum(out, 0.0), op[1]), out)
        elif kind == "invert":
            out = out * (1 - op[1]) + (1.0 - out) * op[1]
        elif kind == "brightcontrast":
            bright, contrast = op[1], op[2]
            a = 1.0 + contrast
            out = np.maximum(a * out + (bright - contrast * 0.5), 0.0)
        elif kind == "hsv":
            hue, sat, val, fac = op[1:]
            hsv = np.array([colorsys.rgb_to_hsv(*p) for p in np.clip(out, 0.0, None)])
            hsv[:, 0] = (hsv[:, 0] + hue + 0.5) % 1.0
            hsv[:, 1] = np.clip(hsv[:, 1] * sat, 0.0, 1.0)
            hsv[:, 2] = hsv[:, 2] * val
            new = np.array([colorsys.hsv_to_rgb(*p) for p in hsv])
            out = out * (1 - fac) + new * fac
        elif kind == "curves":
            fac, tables = op[1], op[2]
            x = np.linspace(0.0, 1.0, 257)
            new = np.stack([np.interp(out[:, c], x, tables[c]) for c in range(3)], axis=1)
            out = out * (1 - fac) + new * fac
    return out


def image_pixels(use: ImageUse) -> np.ndarray:
    """(H, W, 4) float32 linear RGBA of an image as its node reads it (row 0 at the bottom),
    scaled down to MAX_TEXTURE on its longest side by averaging, colour operations applied."""
    img = use.image
    w, h = int(img.size[0]), int(img.size[1])
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(h, w, 4)
    space = img.colorspace_settings.name
    if not img.is_float and space.lower().startswith("srgb"):
        px[..., :3] = srgb_to_linear(px[..., :3])
    step = max(1, -(-max(w, h) // MAX_TEXTURE))
    if step > 1:
        h2, w2 = h // step, w // step
        px = px[:h2 * step, :w2 * step].reshape(h2, step, w2, step, 4).mean(axis=(1, 3))
    if use.ops:
        rgb = _apply_ops(px[..., :3].reshape(-1, 3), use.ops)
        px[..., :3] = rgb.reshape(px.shape[0], px.shape[1], 3)
    return np.ascontiguousarray(px, np.float32)


def _surface_shader(mat):
    nt = mat.node_tree
    outputs = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"]
    outputs.sort(key=lambda n: (not n.is_active_output, n.target not in ("ALL", "CYCLES")))
    for out in outputs:
        if out.target not in ("ALL", "CYCLES"):
            continue
        src = linked_socket(out.inputs.get("Surface"))
        if src is not None:
            return src[0]
    return None


def read_surface(mat, has_nodes: bool) -> Surface:
    """The lightmap view of a material (None: Blender's default grey)."""
    if mat is None:
        return Surface()
    if not has_nodes:
        return Surface(albedo=_rgb(mat.diffuse_color))
    node = _surface_shader(mat)
    if node is None:
        return Surface(albedo=np.zeros(3), notes=["no surface shader: black"])
    known = ("BSDF_PRINCIPLED", "BSDF_DIFFUSE", "BSDF_TRANSPARENT", "EMISSION", "BACKGROUND", "MIX_SHADER",
             "ADD_SHADER")
    if node.type not in known and not any(n.type in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE") for n in mat.node_tree.nodes):
        return Surface(albedo=_rgb(mat.diffuse_color),
                       notes=[f"surface shader {node.type.lower()} is not diffuse: its viewport colour is used"])
    s = _shader(node, [])
    s.notes = list(dict.fromkeys(s.notes))
    return s


def _alpha_image(src):
    """The Image Texture whose Alpha output `src` is, or None."""
    return src[0] if src is not None and src[0].type == "TEX_IMAGE" and src[1].name == "Alpha" else None


def _alpha_mask_image(src):
    """The Image Texture under an alpha cut-off as Blender's glTF importer builds one for alphaMode
    MASK, 1 − (alpha < cutoff), or as Greater Than or Round on the alpha; None for anything else.
    The image's alpha stands for the mask: a mask's alpha is 0 or 1 nearly everywhere, and reading
    the threshold as such would lose the leaves of every imported plant to opaque cards."""
    if src is None or src[0].type != "MATH":
        return None
    math = src[0]
    if math.operation in ("GREATER_THAN", "ROUND"):
        return _alpha_image(linked_socket(math.inputs[0]))
    if math.operation == "SUBTRACT" and not math.inputs[0].is_linked and math.inputs[0].default_value == 1.0:
        inner = linked_socket(math.inputs[1])
        if inner is not None and inner[0].type == "MATH" and inner[0].operation == "LESS_THAN":
            return _alpha_image(_alpha_times_attribute(linked_socket(inner[0].inputs[0])))
    return None


def _alpha_times_attribute(src):
    """The image alpha in image alpha × Color Attribute alpha (the importer's alpha with COLOR_0),
    whose attribute part the bake leaves out; `src` itself otherwise."""
    if src is None or src[0].type != "MATH" or src[0].operation != "MULTIPLY":
        return src
    inputs = [linked_socket(sock) for sock in list(src[0].inputs)[:2]]
    images = [i for i in inputs if _alpha_image(i) is not None]
    others = [i for i in inputs if _alpha_image(i) is None]
    if len(images) == 1 and others[0] is not None and others[0][0].type in ("VERTEX_COLOR", "ATTRIBUTE"):
        return images[0]
    return src


def _shader(node, notes) -> Surface:
    t = node.type
    if t == "BSDF_PRINCIPLED":
        base, image, attr = colour(_input(node, "Base Color"), notes)
        diffuse = (1.0 - _const(_input(node, "Metallic"))) * \
            (1.0 - _const(_input(node, "Transmission Weight", "Transmission")))
        s = Surface(albedo=base * diffuse, albedo_image=image, colour_attribute=attr, notes=notes)
        alpha = _input(node, "Alpha")
        src = linked_socket(alpha)
        mask = _alpha_image(src) or _alpha_mask_image(src)
        if mask is not None:
            s.opacity_image = image_use(mask, notes)
        elif src is not None:
            notes.append(f"the alpha of '{node.name}' comes from a {src[0].type.lower()} node: its value is used")
            s.opacity = _const(alpha, 1.0)
        else:
            s.opacity = _const(alpha, 1.0)
        ecol = _input(node, "Emission Color", "Emission")
        if ecol is not None:
            e, eimg, _ = colour(ecol, notes)
            if eimg is not None:
                notes.append("an emission texture is averaged")
                e = e * image_pixels(eimg)[..., :3].reshape(-1, 3).mean(axis=0)
            s.emission = e * _const(_input(node, "Emission Strength"), 1.0)
        return s
    if t == "BSDF_DIFFUSE":
        base, image, attr = colour(_input(node, "Color"), notes)
        return Surface(albedo=base, albedo_image=image, colour_attribute=attr, notes=notes)
    if t == "BSDF_TRANSPARENT":
        return Surface(albedo=np.zeros(3), opacity=0.0, notes=notes)
    if t in ("EMISSION", "BACKGROUND"):
        e, eimg, _ = colour(_input(node, "Color"), notes)
        if eimg is not None:
            notes.append("an emission texture is averaged")
            e = e * image_pixels(eimg)[..., :3].reshape(-1, 3).mean(axis=0)
        return Surface(albedo=np.zeros(3), emission=e * _const(_input(node, "Strength"), 1.0), notes=notes)
    if t in ("MIX_SHADER", "ADD_SHADER"):
        shaders = [s for s in node.inputs if s.type == "SHADER"]
        parts = [linked_socket(s) for s in shaders]
        subs = [(_shader(p[0], notes) if p is not None else Surface(albedo=np.zeros(3))) for p in parts]
        if t == "ADD_SHADER":
            a, b = subs
            out = _pick_textured(a, b)
            out.albedo = a.albedo + b.albedo
            out.emission = a.emission + b.emission
            out.opacity = min(1.0, a.opacity + b.opacity)
            return out
        fac_sock = _input(node, "Fac")
        a, b = subs
        src = linked_socket(fac_sock)
        transparent = [p is not None and p[0].type == "BSDF_TRANSPARENT" for p in parts]
        if src is not None and src[0].type == "TEX_IMAGE" and src[1].name == "Alpha" and transparent[0]:
            b.opacity_image = image_use(src[0], notes)  # the classic leaf: Transparent ↔ BSDF by alpha
            return b
        if src is not None:
            notes.append(f"'{node.name}' has a linked factor: its value is used")
        f = min(max(_const(fac_sock, 0.5), 0.0), 1.0)
        if transparent[0] or transparent[1]:
            solid, weight = (b, f) if transparent[0] else (a, 1.0 - f)
            solid.opacity *= weight
            return solid
        out = _pick_textured(a, b)
        out.albedo = a.albedo * (1 - f) + b.albedo * f
        out.emission = a.emission * (1 - f) + b.emission * f
        out.opacity = a.opacity * (1 - f) + b.opacity * f
        return out
    found = [n for n in node.id_data.nodes if n.type in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE")]
    notes.append(f"surface shader {t.lower()} is not diffuse: " +
                 ("its material's first Principled/Diffuse node is used" if found else "black"))
    return _shader(found[0], notes) if found else Surface(albedo=np.zeros(3), notes=notes)


def _pick_textured(a: Surface, b: Surface) -> Surface:
    first = a if (a.albedo_image or a.colour_attribute is not None) else b
    return Surface(albedo=first.albedo, albedo_image=first.albedo_image, colour_attribute=first.colour_attribute,
                   opacity=first.opacity, opacity_image=a.opacity_image or b.opacity_image,
                   emission=first.emission, notes=a.notes)




def render_uv_name(me) -> Optional[str]:
    """The UV map Cycles reads when a texture names none: the one marked for rendering."""
    for layer in me.uv_layers:
        if layer.active_render:
            return layer.name
    return me.uv_layers[0].name if len(me.uv_layers) else None


def corner_uvs(me, loops: np.ndarray, name: Optional[str]) -> Optional[np.ndarray]:
    """(T, 3, 2) UVs of a UV map at the loops of each triangle; None when the map is missing."""
    name = name or render_uv_name(me)
    if name is None or name not in me.uv_layers:
        return None
    flat = np.empty(len(me.loops) * 2, np.float64)
    me.uv_layers[name].uv.foreach_get("vector", flat)
    return flat.reshape(-1, 2)[loops]


def corner_colours(me, loops: np.ndarray, name: str) -> Optional[np.ndarray]:
    """(T, 3, 3) linear RGB of a colour attribute at the loops of each triangle ("" = the render
    colour attribute); per point attributes are read through each loop's vertex."""
    attrs = me.color_attributes
    if not len(attrs):
        return None
    attr = attrs.get(name) if name else None
    if attr is None:
        index = getattr(attrs, "render_color_index", 0)
        attr = attrs[index] if 0 <= index < len(attrs) else attrs[0]
    n = len(attr.data)
    flat = np.empty(n * 4, np.float32)
    attr.data.foreach_get("color", flat)  # 'color' is linear for byte and float attributes alike
    rgb = flat.reshape(-1, 4)[:, :3].astype(np.float64)
    if attr.domain == "POINT":
        verts = np.empty(len(me.loops), np.int64)
        me.loops.foreach_get("vertex_index", verts)
        rgb = rgb[verts]
    return rgb[loops]


@dataclass
class SlotRows:
    """An object's material slots as rows: constant albedo, emission and opacity per slot, and the
    Surfaces themselves for what varies over the surface (images, colour attributes)."""
    albedo: np.ndarray  # (k, 3)
    emission: np.ndarray  # (k, 3)
    opacity: np.ndarray  # (k,)
    surfaces: list

    @staticmethod
    def of(surfaces: list) -> "SlotRows":
        return SlotRows(np.array([s.albedo for s in surfaces], float).reshape(-1, 3),
                        np.array([s.emission for s in surfaces], float).reshape(-1, 3),
                        np.array([s.opacity for s in surfaces], float), surfaces)

    @property
    def varies(self) -> bool:
        return any(s.albedo_image or s.opacity_image or s.colour_attribute is not None for s in self.surfaces)


class TextureTable:
    """The images a scene's materials read, one texture per distinct use, and the per-triangle
    arrays that point into them."""

    def __init__(self):
        self.uses: dict = {}  # ImageUse -> texture index
        self.images: list = []
        self.extensions: list = []
        self.interpolations: list = []
        self.any_texture = self.any_opacity = False

    def texture(self, use: ImageUse) -> int:
        if use not in self.uses:
            self.uses[use] = len(self.images)
            self.images.append(image_pixels(use))
            self.extensions.append(use.extension)
            self.interpolations.append(use.interpolation)
        return self.uses[use]

    def triangles(self, rows: SlotRows, g, mi: np.ndarray, copies: int, albedo: np.ndarray, log) -> dict:
        """Opacity, texture indices and texture UVs of a placed geometry's triangles (`mi`: slot per
        triangle, `copies` instances of geometry `g` after one another); `albedo` (its rows) is
        scaled in place by colour attributes."""
        n = len(mi)
        out = {"opacity": rows.opacity[mi].astype(np.float32)}
        if rows.opacity.min() < 1.0:
            self.any_opacity = True
        if not rows.varies:
            return out
        albedo_tex = np.full(n, -1, np.int32)
        opacity_tex = np.full(n, -1, np.int32)
        tex_uvs = np.zeros((n, 3, 2), np.float32)
        for k, s in enumerate(rows.surfaces):
            sel = mi == k
            if not sel.any():
                continue
            if s.colour_attribute is not None:
                cols = g.colour(s.colour_attribute)
                if cols is None:
                    log(f"a material reads colour attribute '{s.colour_attribute or 'render'}', which the mesh lacks")
                else:
                    albedo[sel] *= np.tile(cols.mean(axis=1), (copies, 1))[sel]
            for use, target in ((s.albedo_image, albedo_tex), (s.opacity_image, opacity_tex)):
                if use is None:
                    continue
                uvs = g.uv(use.uv)
                if uvs is None:
                    log(f"image '{use.image.name}' is read through UV map '{use.uv or 'render'}', which the mesh "
                        "lacks: it is left out")
                    continue
                target[sel] = self.texture(use)
                tex_uvs[sel] = np.tile(uvs, (copies, 1, 1))[sel]
        self.any_texture |= bool((albedo_tex >= 0).any() or (opacity_tex >= 0).any())
        out.update(albedo_texture=albedo_tex, opacity_texture=opacity_tex, tex_uvs=tex_uvs)
        return out

    def finish(self, parts: list) -> dict:
        """The scene's arrays from every placement's `triangles` output, in order: None where the
        whole scene is untextured or opaque."""
        out = {"textures": None, "tex_uvs": None, "albedo_texture": None, "opacity": None, "opacity_texture": None}
        if self.any_opacity or self.any_texture:
            out["opacity"] = np.concatenate([p["opacity"] for p in parts]) if parts else None
        if self.any_texture:
            def cat(key, fill, shape, dtype):
                return np.concatenate([p[key] if key in p else np.full((len(p["opacity"]),) + shape, fill, dtype)
                                       for p in parts])
            out["albedo_texture"] = cat("albedo_texture", -1, (), np.int32)
            out["opacity_texture"] = cat("opacity_texture", -1, (), np.int32)
            out["tex_uvs"] = cat("tex_uvs", 0.0, (3, 2), np.float32).astype(np.float64)
            out["textures"] = Textures.pack(self.images, self.extensions, self.interpolations)
        return out
