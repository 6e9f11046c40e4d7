"""The command line's parser: the commands (bake, compare, export-gltf), their flags made from the
settings declared in options.py, and the settings a parsed command line gives (`settings_from_args`)."""
from __future__ import annotations

import argparse

from .. import __version__, options
from ..run import bake as bake_mod
from ..lightmap import images
from ..errors import BakeError
from ..estimators import compare_defaults


def build_parser(prog: str = "python -m detp_bake", with_scene_path: bool = True) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Bake diffuse irradiance lightmaps "
                                     "with photon density estimation (DETP).")
    parser.add_argument("--version", action="version", version=f"detp_bake {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bake", help="bake lightmaps for a .blend file")
    c = sub.add_parser("compare", help="bake the same photons with several estimators, side by side")
    c.add_argument("--estimators", nargs="+", default=compare_defaults(), metavar="ESTIMATOR",
                   help="estimators to compare; the first is the reference "
                                             "(default: %s)" % " ".join(compare_defaults()))
    for p in (b, c):
        _bake_arguments(p, with_scene_path)
    b.add_argument("--gltf", default=None, metavar="OUT.glb",
                   help="after the bake, also write the scene as a .glb with its lightmaps (docs/gltf.md); the "
                        "scene and the .blend are left as they are")
    _export_arguments(sub.add_parser("export-gltf", help="write a baked scene as a .glb with its lightmaps "
                                     "(MOZ_lightmap, RGBE)"), with_scene_path)
    return parser


def _export_arguments(e, with_scene_path):
    if with_scene_path:
        e.add_argument("scene", help="the baked .blend file")
    e.add_argument("--lightmaps", required=True, metavar="DIR", help="the bake's output folder (its report.json)")
    e.add_argument("--out", required=True, metavar="OUT.glb", help="the .glb file to write")
    e.add_argument("--estimator", default=None,
                   help="whose lightmaps, when DIR holds a comparison (default: the one the report holds)")
    e.add_argument("--uv-layer", default=None,
                   help=f"the lightmap UV layer (default '{options.UV_LAYER}'), written as TEXCOORD_1")
    e.add_argument("--json", action="store_true", help="print a JSON summary on stdout instead of the file")


def _bake_arguments(b, with_scene_path):
    if with_scene_path:
        b.add_argument("scene", help="the .blend file to bake")
    b.add_argument("--objects", nargs="+", metavar="NAME", help="objects to bake (default: all visible meshes)")
    _option_arguments(b)
    b.add_argument("--uv-layer", default=None,
                   help=f"lightmap UV layer (default '{options.UV_LAYER}', created with xatlas charts if missing)")
    b.add_argument("--out", required=True, help="output folder")
    b.add_argument("--format", default=",".join(bake_mod.BakeSettings.formats),
                   help=f"comma-separated: {','.join(images.WRITERS)} (default %(default)s)")
    b.add_argument("--half", action="store_true", help="write half-float EXR")
    b.add_argument("--keep-raw", action="store_true",
                   help="also write each lightmap before denoising, as <object>.<estimator>.raw.exr")
    b.add_argument("--scheduler", default="", metavar="ADDRESS",
                   help="trace the photons on a Dask cluster: its scheduler, e.g. tcp://10.0.0.5:8786 "
                        "(needs the dask and distributed packages; README: Baking on a cluster)")
    b.add_argument("--workers", type=int, default=0, metavar="N",
                   help="trace the photons on N worker processes of this machine (a Dask LocalCluster)")
    b.add_argument("--connect-timeout", type=float, default=options.CONNECT_TIMEOUT, metavar="SECONDS",
                   help="give up on the scheduler (or its first worker) after this long (default %(default)g)")
    b.add_argument("--apply", action="store_true", help="wire the lightmaps into the materials")
    b.add_argument("--frames", default=None, metavar="A-B[:STEP]",
                   help="bake every frame of this range: <object>.<estimator>.<frame:04d>.exr")
    b.add_argument("--moving", nargs="+", default=[], metavar="NAME",
                   help="with --frames: treat these objects as moving (default: found by evaluating the frames)")
    b.add_argument("--static", nargs="+", default=[], metavar="NAME",
                   help="with --frames: treat these objects as static")
    b.add_argument("--force", action="store_true",
                   help="bake again the objects' lightmaps (with --frames: the frames) unchanged since the last "
                        "bake into --out (kept by default)")
    b.add_argument("--save", default=None, metavar="OUT.blend", help="save the baked .blend here")
    b.add_argument("--json", action="store_true", help="print a JSON summary on stdout instead of the file list")


class _Given(argparse.Action):
    """Store the value and note the setting as given (options.unused: a flag that does nothing)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.given = set(getattr(namespace, "given", ())) | {self.dest}


def _option_arguments(b) -> None:
    """One option per setting of options.py: its default, choices and help from there."""
    b.set_defaults(given=frozenset())
    for opt in options.OPTIONS:
        default = "on" if opt.default else "off"
        if opt.kind is bool:
            b.add_argument(opt.flag, action=argparse.BooleanOptionalAction, default=opt.default,
                           help=f"{opt.help[0].lower()}{opt.help[1:]} (default {default})")
            continue
        text = opt.help[0].lower() + opt.help[1:]
        if opt.kind is tuple:  # a list of names
            b.add_argument(opt.flag, nargs="+", default=list(opt.default), metavar=opt.metavar,
                           help=text.replace("%", "%%"))
            continue
        choices = [c[0] for c in opt.choice_list] or None
        if choices:
            text += " (" + "; ".join(f"{v}: {h}" for v, _, h in opt.choice_list) + ")"
        b.add_argument(opt.flag, type=opt.kind, default=opt.default, choices=choices, metavar=opt.metavar,
                       action=_Given, help=text.replace("%", "%%") + " (default %(default)s)")


def settings_from_args(args) -> bake_mod.BakeSettings:
    """The bake settings of the parsed command line (BakeSettings.from_choices, as the panel)."""
    formats = tuple(f.strip().lower() for f in args.format.split(",") if f.strip())
    idle = options.unused(getattr(args, "given", ()), args.lightmaps)
    if idle:
        raise BakeError(idle)
    return bake_mod.BakeSettings.from_choices({o.name: getattr(args, o.name) for o in options.OPTIONS},
                                              formats=formats, half=args.half, keep_raw=args.keep_raw)
