"""What every operator needs: the bake settings from the scene's properties, the objects to bake,
and a Blender scene exported for the core."""
import bpy

from ..detp_bake import blender, options
from ..detp_bake.errors import BakeError
from ..detp_bake.run import memory
from ..detp_bake.lightmap import texels
from ..detp_bake.run.bake import BakeSettings


def preferences(context):
    addon = context.preferences.addons.get(__package__.rpartition(".")[0])
    return addon.preferences if addon is not None else None


def cluster(context):
    """The Dask cluster of the preferences (distributed.py), not yet connected, or a null context."""
    import contextlib
    prefs = preferences(context)
    address = prefs.scheduler_address.strip() if prefs is not None else ""
    if not address:
        return contextlib.nullcontext()
    check_online(address)
    from ..detp_bake.run.distributed import Cluster
    return Cluster(address)


def check_online(address: str) -> None:
    """A scheduler on another machine is the network (the manifest's `network` permission): only
    with Blender's Allow Online Access on (BakeError saying where to turn it on otherwise). One on
    this machine (127.0.0.1, localhost, ::1) needs no network."""
    from urllib.parse import urlsplit
    host = urlsplit(address if "://" in address else f"//{address}").hostname or ""
    if host.startswith("127.") or host in ("localhost", "::1"):
        return
    if not getattr(bpy.app, "online_access", True):
        from ..detp_bake.errors import BakeError
        raise BakeError(f"the Dask scheduler {address} of the preferences needs Allow Online Access "
                        "(Preferences › System › Network), or clear the scheduler address to bake here")


def bake_settings(context, estimator=None) -> BakeSettings:
    """The bake settings of the scene's properties (BakeSettings.from_choices, as the command line);
    what only the panel has: threads and the memory budget fall back on the preferences, the disc
    radius is in texels or in metres (radius_mode), spacing applies with shadow rays only."""
    s = context.scene.detp_bake
    prefs = preferences(context)
    choices = {o.name: getattr(s, o.name) for o in options.OPTIONS if hasattr(s, o.name)}
    choices["shadowmask"] = shadowmask_lights(context.scene)
    choices["threads"] = s.threads or (prefs.threads if prefs is not None else 0)
    choices["memory_budget_mb"] = prefs.memory_budget if prefs is not None else options.default("memory_budget_mb")
    if estimator:
        choices["estimator"] = estimator
    if s.radius_mode != "WORLD":
        choices["radius"] = options.BY_NAME["radius"].auto
    if s.direct != "sampled":
        choices["indirect_spacing"] = options.BY_NAME["indirect_spacing"].auto
    return BakeSettings.from_choices(choices, formats=tuple(f.lower() for f in sorted(s.formats)) or ("exr",))


def shadowmask_lights(scene) -> tuple:
    """The names of the scene's lights whose Shadowmask toggle is on, in name order (the mask's
    channel order): the command line's --shadowmask list."""
    return tuple(sorted(o.name for o in scene.objects if o.type == "LIGHT" and o.detp_bake.shadowmask))


def output_directory(context) -> str:
    return bpy.path.abspath(context.scene.detp_bake.output_directory)


def bake_targets(context) -> list:
    """Selected meshes marked Include, or every rendered included mesh when none is selected (what
    F12 renders: a mesh hidden in the viewport but rendered is baked too)."""
    rendered = blender.rendered_names(context.view_layer)

    def ok(o):
        return o.type == "MESH" and o.name in rendered and o.detp_bake.include
    picked = [o for o in context.selected_objects if ok(o)]
    return picked or [o for o in context.scene.objects if ok(o)]


def uv_layers(objects) -> dict:
    """Per-object UV layer names that the user set explicitly (the default may be created)."""
    return {o.name: o.detp_bake.uv_layer for o in objects if o.detp_bake.uv_layer != blender.DEFAULT_UV}


def export(context, objects, log, created=None):
    """The scene for the core, with each object's lightmap size (override, density or fixed)."""
    s = context.scene.detp_bake
    sizes = {o.name: o.detp_bake.resolution or s.resolution for o in objects}
    prefs = preferences(context)
    budget = memory.geometry_budget(prefs.memory_budget if prefs is not None else 0)
    scene = blender.export_scene(context.scene, context.evaluated_depsgraph_get(), [o.name for o in objects],
                                       uv_layers(objects), sizes, log, created, max_bytes=budget or None,
                                       atlas=bake_settings(context))
    if s.resolution_mode == "DENSITY" and s.lightmaps != "atlas":
        for obj in scene.objects:
            if obj.bake and not context.scene.objects[obj.name].detp_bake.resolution:
                sl = obj.triangles
                obj.resolution = texels.resolution_for_density(scene.positions[sl], scene.uvs[sl], s.texel_density)
    return scene


ACTIVE = None  # the BlenderJob (operators/job.py) of the running bake or compare, until it is finished


def idle(cls, context) -> bool:
    """The poll of every operator that runs a job: one job at a time per Blender session (two would
    share numba's thread pool; detp_bake/run/job.py holds the lock), saying why when one runs."""
    from ..detp_bake.run import job
    busy = job.busy_message() or (f"a {ACTIVE.kind} is finishing" if ACTIVE is not None else None)
    if busy:
        cls.poll_message_set(busy)
        return False
    return context.scene is not None


def apply_probes(scene, folder: str, log) -> int:
    """Light the scene's objects marked Probe Light with the probes.npz in `folder`, if there is
    one; how many objects."""
    try:
        return len(blender.apply_marked(scene, folder))
    except BakeError as exc:
        log(str(exc))
        return 0
