"""Test set-up: the repository root on sys.path, and Blender's user folder in a temp dir so the
bpy wheel writes nothing to the user's home."""
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


@pytest.fixture(scope="session")
def bpy():
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
