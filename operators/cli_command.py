"""`blender -b scene.blend -c detp_bake bake|compare ...`: the command-line parser of
`python -m detp_bake`, run on the scene Blender has open."""
import bpy

_handle = None


def execute(argv) -> int:
    from ..detp_bake import cli
    return cli.main(list(argv), bl_scene=bpy.context.scene)


def register():
    global _handle
    if hasattr(bpy.utils, "register_cli_command"):
        _handle = bpy.utils.register_cli_command("detp_bake", execute)


def unregister():
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
