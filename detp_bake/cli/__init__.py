"""Command line: `python -m detp_bake bake SCENE.blend ...` with the bpy wheel, and the same
parser behind Blender's `blender -b SCENE.blend -c detp_bake bake ...`.

Every check that can fail (settings, the .blend path, the output folder, object names, UV layers)
runs before tracing starts. stdout lists the files written (or, with --json, a summary); progress,
warnings and Blender's own messages go to stderr (output.py). Ctrl+C or SIGTERM cancels cleanly
(interrupt.py): exit code 130, nothing written.
"""
from .arguments import build_parser, settings_from_args  # noqa: F401 (the package's names)
from .commands import StderrProgress, run_bake, run_compare, run_export_gltf, run_frames  # noqa: F401
from .main import main  # noqa: F401
