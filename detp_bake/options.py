"""Every bake setting a person chooses, declared once: its default, range, choices, help and label.

The command line (cli.py) makes its options from this list, the panel (ui/properties.py) its
properties, BakeSettings and EstimatorSettings take their defaults from it and `check` its ranges,
and both front ends turn what the person chose into settings through one function
(`BakeSettings.from_choices`), so the panel and the command line cannot drift apart.

A setting that may be automatic has an `auto` value (0 or −1) that both front ends show for it; the
core reads it as None where its field is Optional (bounces, disc radii).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional


MAX_PHOTONS = 1_000_000_000
PHOTONS_PER_TEXEL = 16  # automatic photon count: this many per lightmap texel to bake ...
AUTO_PHOTONS = (1_000_000, 64_000_000)  # ... within these
MAX_RESOLUTION = 16384
MAX_BOUNCES = 1024
MAX_DIRECT_SAMPLES = 4096
MAX_SPACING = 8
AUTO_SPACING, AUTO_FROM = 2, 256  # indirect spacing 0: every second texel on lightmaps of 256² and more (sites.py)
MAX_MARGIN = 4096
CONNECT_TIMEOUT = 10.0  # seconds to wait for a Dask scheduler and its first worker
UV_LAYER = "Lightmap"  # the lightmap UV layer's default name
DIRECT_MODES = ("sampled", "photons")
# DETP disc radius in texels when not set: wide where the discs see indirect light only (it is smooth:
# wider discs, less noise; best at equal time, benchmarks/quality.py), narrow where they see every
# segment (the paper's mode, where discs blur hard shadows).
RADIUS_TEXELS_INDIRECT = 3.0
RADIUS_TEXELS_ALL = 1.5
KERNELS = ("constant", "epanechnikov")
MAX_SHADOWMASK = 4  # lights in one shadowmask: the RGBA channels


@dataclass(frozen=True)
class Option:
    """One setting. `name` is its field in BakeSettings (EstimatorSettings when `estimator`);
    `kind` int, float, bool or str; `choices` ((value, label, help), …) for a choice (or a function
    that returns them, for the estimator registry, read when asked); `auto` the value
    that means automatic (None where there is none); `flag` the command line's option; `unit` how
    the panel shows a number (NONE, PERCENTAGE, TIME, LENGTH)."""
    name: str
    kind: type
    default: Any
    label: str
    help: str
    minimum: Optional[float] = None
    maximum: Optional[float] = None
    soft_maximum: Optional[float] = None
    choices: tuple = ()
    auto: Any = None
    estimator: bool = False
    unit: str = "NONE"
    metavar: Optional[str] = None
    lightmaps: str = ""  # the one `lightmaps` mode this setting does anything in ('' for all)

    @property
    def choice_list(self) -> tuple:
        return tuple(self.choices()) if callable(self.choices) else self.choices

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def core(self, value):
        """The value the core reads for what a front end holds: None for the automatic value of an
        Optional field, a float to seven significant digits."""
        if self.auto is not None and value == self.auto and self.name in OPTIONAL:
            return None
        if self.kind is tuple:  # names: a list (command line, the panel's toggles) or comma-separated text
            if isinstance(value, str):
                value = [v.strip() for v in value.split(",")]
            return tuple(v for v in (value or ()) if v)
        if self.kind is float and isinstance(value, float):
            # Blender keeps a float property in single precision (0.65 reads 0.6499999761581421):
            # seven digits give the panel and the command line the same number.
            return float(f"{value:.7g}")
        return value

    def check(self, value) -> Optional[str]:
        """Why `value` (as the core reads it) cannot work, or None."""
        if value is None and self.name in OPTIONAL:
            return None
        if self.kind is tuple:
            if not isinstance(value, (tuple, list)) or not all(isinstance(v, str) and v for v in value):
                return "must be a list of names"
            if len(set(value)) != len(value) or len(value) > MAX_SHADOWMASK:
                return f"must name at most {MAX_SHADOWMASK} different lights (one per RGBA channel)"
            return None
        if self.choices:
            names = [c[0] for c in self.choice_list]
            return None if value in names else f"choose one of {', '.join(names)}"
        if self.kind is int and not (isinstance(value, int) and not isinstance(value, bool)):
            return "must be a whole number"
        if self.kind in (int, float):
            try:
                ok = float(value) == float(value) and abs(float(value)) != float("inf")
            except (TypeError, ValueError):
                ok = False
            low = self.minimum if self.auto is None or self.name in OPTIONAL else min(self.minimum, self.auto)
            if not ok or (low is not None and value < low) or (self.maximum is not None and value > self.maximum):
                return "must be " + self.range_text()
        return None

    def range_text(self) -> str:
        def num(v):
            return f"{int(v):,}" if self.kind is int else f"{v:g}"
        auto = f"{num(self.auto)} (automatic) or " if self.auto is not None and self.name not in OPTIONAL else ""
        if self.maximum is None:
            return f"{auto}at least {num(self.minimum)}"
        return f"{auto}between {num(self.minimum)} and {num(self.maximum)}"


# The estimators (name, label, help), in the order the panel and the help list them; each registers
# under its name in estimators/ (which takes its label and help from here, and checks it is listed).
ESTIMATORS = (
    ("texel_histogram", "Texel Histogram",
     "Each photon's flux into the texel it lands in: no blur, white noise (for OIDN)"),
    ("disc_index", "DETP: Disc Index", "Tangent-disc density estimation with the discs indexed in a BVH (fastest)"),
    ("sphere_cache", "DETP: Sphere Cache", "Tangent-disc density estimation through Lastra's sphere cache"),
    ("hybrid", "DETP: Hybrid", "For frame ranges: the static objects' discs indexed once for all frames, the moving "
     "objects' texels by the sphere cache (or a disc index) every frame"),
    ("detp", "DETP: Brute Force", "Every segment against every disc: slow, the reference the others match"),
    ("photon_map", "Photon Map", "Jensen's k-nearest-neighbour photon map: noisy, darkens edges"),
)


# Fields whose automatic value the core holds as None.
OPTIONAL = ("bounces", "radius_texels", "radius")

OPTIONS = (
    Option("estimator", str, "texel_histogram", "Estimator", "Density estimator that turns photons into irradiance",
           choices=ESTIMATORS),
    Option("photons", int, 0, "Photons", "Photons traced from the lights: more means less noise; 0: automatic, "
           f"{PHOTONS_PER_TEXEL} per lightmap texel to bake, times the surfaces' mean reflectance with shadow rays "
           f"({AUTO_PHOTONS[0]:,} to {AUTO_PHOTONS[1]:,}); with a noise "
           f"target or a time limit the most to trace ({MAX_PHOTONS:,} when automatic)",
           minimum=1, maximum=MAX_PHOTONS, soft_maximum=50_000_000, auto=0),
    Option("direct", str, "sampled", "Direct Light", "How direct light is found",
           choices=(("sampled", "Shadow Rays", "Direct light sampled with shadow rays at every texel; photons carry "
                     "indirect light only (sharp shadows, least noise)"),
                    ("photons", "Photons", "Photons carry direct light too and the estimator sees every segment "
                     "(the paper's experiments)"))),
    Option("direct_samples", int, 16, "Shadow Rays", "Shadow rays per texel for each light with extent (area, "
           "sphere, sun disc, sky, emissive meshes); point lights need one",
           minimum=1, maximum=MAX_DIRECT_SAMPLES, soft_maximum=256),
    Option("indirect_spacing", int, 0, "Indirect Spacing", "With shadow rays for direct light: estimate indirect "
           f"light every this many texels and blend between them (0: automatic, {AUTO_SPACING} on lightmaps "
           f"of {AUTO_FROM}² and more; 1: every texel)", minimum=1, maximum=MAX_SPACING, auto=0,
           metavar="TEXELS"),
    Option("target_noise", float, 0.0, "Noise Target", "Stop tracing once every lightmap's noise is at most this many "
           "per cent of the scene's mean irradiance (0: off); Photons is then the most to trace", minimum=0.0, maximum=100.0,
           soft_maximum=10.0, unit="PERCENTAGE", metavar="PERCENT"),
    Option("time_limit", float, 0.0, "Time Limit", "Stop tracing before the bake has run this many seconds (0: off)",
           minimum=0.0, soft_maximum=3600.0, unit="TIME", metavar="SECONDS"),
    Option("denoise", bool, True, "Denoise", "Denoise the lightmaps with Intel Open Image Denoise (chart-aware; "
           "needs the pyoidn package)"),
    Option("bounces", int, -1, "Bounces", "Diffuse bounces before a photon lands (-1: the scene's Cycles Light "
           "Paths › Diffuse)", minimum=0, maximum=MAX_BOUNCES, soft_maximum=16, auto=-1),
    Option("seed", int, 0, "Seed", "Random seed: the same seed gives the same lightmaps", minimum=0),
    Option("resolution", int, 128, "Resolution", "Lightmap width and height in pixels",
           minimum=1, maximum=MAX_RESOLUTION, soft_maximum=4096, lightmaps="object"),
    Option("lightmaps", str, "object", "Lightmaps", "One lightmap per object, or every object's charts packed "
           "into shared atlases at one texel density (lightmap/atlas.py)",
           choices=(("object", "Per Object", "One lightmap per object, of its own resolution"),
                    ("atlas", "Atlases", "The charts of all baked objects packed into a few atlases at one texel "
                     "density: atlas_0.<estimator>.exr, …"))),
    Option("texel_density", float, 32.0, "Texels per Metre", "Lightmap texels per metre of surface: of every "
           "object in an atlas (times the object's own Density Scale), or of each object's own lightmap when "
           "sizing by density", minimum=0.01, soft_maximum=1024.0, metavar="TEXELS", lightmaps="atlas"),
    Option("atlas_size", int, 1024, "Atlas Size", "Width and height of each atlas in pixels; more atlases are "
           "added as needed", minimum=16, maximum=MAX_RESOLUTION, soft_maximum=8192, lightmaps="atlas"),
    Option("atlas_padding", int, 2, "Atlas Padding", "Empty texels between charts in an atlas (at least 2: no "
           "texel is shared under bilinear filtering)", minimum=1, maximum=64, metavar="TEXELS", lightmaps="atlas"),
    Option("atlas_charts", str, "layout", "Atlas Charts", "What is packed into the atlases",
           choices=(("layout", "Object Layouts", "Each object's lightmap UV layer as it is (made with xatlas charts "
                     "where it has none), as one block, scaled to the density and placed"),
                    ("islands", "Islands", "The islands of each object's lightmap UV layer, each scaled to the "
                     "density and placed on its own"),
                    ("smart", "Smart UV", "New islands from Blender's Smart UV Project (fewer seams), placed on "
                     "their own")), lightmaps="atlas"),
    Option("directional", str, "none", "Directional", "Also bake where the light comes from, for normal-mapped "
           "shading (lightmap/sh.py)",
           choices=(("none", "None", "The plain lightmap only"),
                    ("sh", "SH L1", "The plain lightmap (L0) and, per colour channel, the cosine-weighted mean "
                     "incoming direction (L1) in <object>.<estimator>.L1.exr and one RGB file per axis (.L1x, .L1y, "
                     ".L1z.exr), shaded against normal maps by Apply"),
                    ("dominant", "Dominant Direction", "The plain lightmap and one luminance-weighted direction per "
                     "texel with its directionality in <object>.<estimator>.dir.exr (RGB and A)"))),
    Option("shadowmask", tuple, (), "Shadowmask", f"Lights (up to {MAX_SHADOWMASK}) whose shadows go into "
           "<object>.<estimator>.shadowmask.exr, one light per RGBA channel: the share of the light's unshadowed "
           "irradiance that arrives, from the shadow rays", metavar="LIGHT"),
    Option("shadowmask_mode", str, "subtract", "Shadowmask Mode", "What the lightmap keeps of a shadow-masked light",
           choices=(("subtract", "Subtract", "Its direct light is left out of the lightmap (its bounced light stays): "
                     "the real light times the mask adds it at render time"),
                    ("overlay", "Overlay", "Its direct light stays in the lightmap too; the mask only says where its "
                     "shadows are (to darken dynamic objects' light there)"))),
    Option("probes", str, "off", "Light Probes", "Also bake light probes for moving objects: SH L2 of the light "
           "at points in space, written to probes.npz (docs/probes.md)",
           choices=(("off", "Off", "No probes"),
                    ("auto", "Automatic Grid", "A grid over the baked objects' bounds at Probe Spacing, probes kept "
                     "within one spacing of a surface"),
                    ("volumes", "Light Probe Volumes", "One grid per Light Probe Volume object of the scene, its box "
                     "cut by its own resolution"))),
    Option("probe_spacing", float, 1.0, "Probe Spacing", "Automatic probe grid: metres between probes",
           minimum=0.01, soft_maximum=16.0, unit="LENGTH", metavar="METRES"),
    Option("probe_rays", int, 512, "Probe Rays", "Gather rays per probe (its light from the lightmaps, emitters and "
           "sky; lights by shadow rays apart): more is less noise", minimum=16, maximum=65536, soft_maximum=4096),
    Option("margin", int, 16, "Margin", "Pixels of dilation around the UV charts, against seams under filtering",
           minimum=0, maximum=MAX_MARGIN),
    Option("threads", int, 0, "Threads", "Threads for tracing and estimation (0: all cores)", minimum=0,
           maximum=1024),
    Option("memory_budget_mb", int, 0, "Memory Budget (MB)", "Refuse bakes whose peak memory, estimated before "
           "any work, would pass this many megabytes (0: 80 % of the memory free when the bake starts)",
           minimum=0, soft_maximum=65536, metavar="MB"),
    Option("k", int, 100, "Neighbours", "Photon map: hits per estimate; noise is about 1/sqrt(k)",
           minimum=2, soft_maximum=5000, estimator=True),
    Option("radius_texels", float, 0.0, "Radius", "DETP disc radius in texels of each lightmap (0: automatic, "
           f"{RADIUS_TEXELS_INDIRECT:g} with shadow rays for direct light, {RADIUS_TEXELS_ALL:g} "
           "when the discs see every segment): larger is smoother but blurrier",
           minimum=1e-3, soft_maximum=8.0, auto=0.0, estimator=True, metavar="TEXELS"),
    Option("radius", float, 0.0, "Radius", "DETP disc radius in metres (0: in texels instead; overrides the texels)",
           minimum=1e-6, auto=0.0, estimator=True, unit="LENGTH", metavar="METRES"),
    Option("q", float, 0.65, "Sphere Ratio", "Sphere cache: radius ratio of successive spheres (best near 0.6-0.7)",
           minimum=0.05, maximum=0.95, estimator=True),
    Option("kernel", str, "constant", "Kernel", "DETP family: the disc's kernel",
           choices=tuple((k, k.title(), f"{k.title()} kernel over the disc") for k in KERNELS),
           estimator=True),
    Option("hybrid_moving", str, "sphere_cache", "Moving Texels", "Hybrid: how the moving objects' texels are "
           "estimated", choices=(("sphere_cache", "Sphere Cache", "The paper's choice"),
                                 ("disc_index", "Disc Index", "A small index of their own, built every frame")),
           estimator=True),
)
BY_NAME = {o.name: o for o in OPTIONS}


def unused(given, lightmaps: str) -> Optional[str]:
    """Why settings given on the command line (`given`: their names) do nothing with `lightmaps`
    ('object' or 'atlas'), or None. A flag that changes nothing is refused, not ignored: a person
    who sets the atlas size expects atlases. (On the command line, per-object lightmaps are sized
    by --resolution alone; the panel's size by density is a panel setting.)"""
    idle = [BY_NAME[n] for n in BY_NAME if n in given and BY_NAME[n].lightmaps not in ("", lightmaps)]
    if not idle:
        return None
    flags = " and ".join(o.flag for o in idle)
    if lightmaps == "atlas":
        return (f"{flags} does nothing with --lightmaps atlas (atlases are sized by --texel-density and "
                f"--atlas-size): leave it out")
    return (f"{flags} only work{'s' if len(idle) == 1 else ''} with atlases, and these are per-object "
            f"lightmaps (sized by --resolution): add --lightmaps atlas")


def default(name: str):
    """The core's default of setting `name` (None for an automatic Optional one)."""
    o = BY_NAME[name]
    return o.core(o.default)
