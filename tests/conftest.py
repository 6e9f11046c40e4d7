"""Test set-up: the repository root on sys.path, and Blender's user folder in a temp dir so the
bpy wheel writes nothing to the user's home.

Without the bpy wheel (`make test-core`) the core tests run and every test that needs Blender is
skipped for one reason, NO_BPY: a module that imports bpy (directly or through detp_bake.blender)
is skipped as a whole, a test that asks for the `bpy` fixture is skipped alone.

With DETP_BAKE_NEEDS_BLENDER=FILE such a run writes what it skipped for that reason to FILE, one
test or module a line, as pytest arguments (`make test` then runs exactly those with bpy: every
test runs once, with Blender or without, and none can be missed)."""
import importlib.util
import os
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
_user = tempfile.mkdtemp(prefix="detp_bake_blender_user_")
os.environ["BLENDER_USER_RESOURCES"] = _user
os.environ.setdefault("BLENDER_USER_CONFIG", os.path.join(_user, "config"))

CORNELL = ROOT / "sample_scenes" / "cornell_box.blend"
HAVE_BPY = importlib.util.find_spec("bpy") is not None
NO_BPY = "needs Blender: the bpy wheel is not installed in this environment"


class _Module(pytest.Module):
    """A test module that is skipped, not an error, when it cannot import bpy."""

    def collect(self):
        try:
            return super().collect()
        except self.CollectError as exc:
            cause = exc.__cause__
            if not HAVE_BPY and isinstance(cause, ImportError) and cause.name == "bpy":
                pytest.skip(NO_BPY, allow_module_level=True)
            raise


def pytest_collection_modifyitems(config, items):
    """Tests marked `blender` need bpy without asking for the fixture (a subprocess, the CLI)."""
    if HAVE_BPY:
        return
    for item in items:
        if item.get_closest_marker("blender"):
            item.add_marker(pytest.mark.skip(reason=NO_BPY))


_SKIPPED = []


def _note(report) -> None:
    if report.skipped and NO_BPY in str(report.longrepr):
        _SKIPPED.append(f"tests/{report.nodeid}")


def pytest_collectreport(report):
    _note(report)


def pytest_runtest_logreport(report):
    _note(report)


def pytest_sessionfinish(session, exitstatus):
    session.config.detp_bake_status = int(exitstatus)
    path = os.environ.get("DETP_BAKE_NEEDS_BLENDER")
    if path and not HAVE_BPY:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text("".join(f"{n}\n" for n in dict.fromkeys(_SKIPPED)))


def pytest_pycollect_makemodule(module_path, parent):
    if module_path.name.startswith("test_"):
        return _Module.from_parent(parent, path=module_path)
    return None


@pytest.fixture(scope="session")
def bpy():
    if not HAVE_BPY:
        pytest.skip(NO_BPY)
    import bpy as _bpy
    return _bpy


@pytest.fixture
def cornell(bpy):
    """The bundled Cornell box, freshly opened."""
    bpy.ops.wm.open_mainfile(filepath=str(CORNELL))
    return bpy.context.scene


@pytest.fixture
def empty_blend(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def pytest_unconfigure(config):
    """Everything is reported by now: leave past bpy 4.5's exit handlers where they would hang
    (detp_bake.cli.output.exit_hangs: a bake and Blender's glTF exporter in one process)."""
    from detp_bake.cli.output import exit_hangs
    if exit_hangs():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(getattr(config, "detp_bake_status", 1))
