"""`main`: parse, connect a cluster when asked, run the command, and turn its outcome into an exit
code (0; 2 for a refused bake; 130 when cancelled) and stdout's list of files (or --json summary)."""
from __future__ import annotations

import contextlib
import sys
from typing import Optional, Sequence

from ..run import interrupt
from . import output
from ..errors import BakeCancelled, BakeError
from .arguments import build_parser
from .commands import run_bake, run_compare, run_export_gltf


def main(argv: Optional[Sequence[str]] = None, bl_scene=None) -> int:
    parser = build_parser(with_scene_path=bl_scene is None)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help or --version (0), or a bad option (2) that argparse has named
        return int(exc.code or 0)
    run = {"bake": run_bake, "compare": run_compare, "export-gltf": run_export_gltf}[args.command]
    with interrupt.cancel_on_signals() as cancel:
        try:
            with output.quiet_stdout():  # Blender's own prints go to stderr
                with contextlib.ExitStack() as args.resources:  # a cluster, connected past the door
                    args.cluster = None
                    summary = run(args, bl_scene, cancel)
        except BakeError as exc:
            print(f"detp_bake: error: {exc}", file=sys.stderr)
            return 2
        except (BakeCancelled, KeyboardInterrupt):
            print("detp_bake: cancelled: nothing written", file=sys.stderr, flush=True)
            return interrupt.EXIT_CODE
    if args.command == "export-gltf" and not args.json:
        print(summary["gltf"], flush=True)  # the one file written
    else:
        output.written(summary, args.json)
    return interrupt.EXIT_CODE if summary.get("cancelled") else 0
