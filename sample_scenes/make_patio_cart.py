"""Build the detp_bake sample scene "patio_cart": the patio with a cart crossing its courtyard.

A larger quasi-static scene for the hybrid estimator than quasi_static.blend: the whole patio of
make_patio.py (122,318 triangles, sun and sky) stays put while one box "Cart", 1.0 x 0.6 x 0.8 m
(12 triangles), rolls across the open court from west to east over frames 1..16, 2.2 m south of
the fountain: between the fountain and the south bench, clear of the planters (a location
keyframe on every frame, x from -4.5 to 4.5 m, linear). Nothing else is animated.

The cart has the texture UV layer "UVMap" and a "Lightmap" layer by Lightmap Pack (one chart per
face, as in make_quasi_static.py). Deterministic. The .blend is not kept in the repository (it
would be the patio's 2.5 MB again): benchmarks/frames.py --scene patio_cart builds it in memory,
and this script saves it where you like.

Usage (with the bpy module, Blender 4.5 or 5.x):
    python sample_scenes/make_patio_cart.py [OUTPUT.blend]
"""

import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_cornell_box import add_lightmap_uv  # noqa: E402
from make_patio import box, build_patio  # noqa: E402
from make_quasi_static import add_object  # noqa: E402
from make_tree import MeshBuilder, generate, make_material  # noqa: E402

FRAME_START, FRAME_END = 1, 16
CART_SIZE = (1.0, 0.6, 0.8)
CART_Y = -2.2
CART_X = (-4.5, 4.5)
CART_COLOUR = (0.60, 0.45, 0.30)
DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "patio_cart.blend")


def cart_location(frame):
    """Where the Cart stands at `frame`: west to east across the court, at constant speed."""
    t = (frame - FRAME_START) / (FRAME_END - FRAME_START)
    return (CART_X[0] + t * (CART_X[1] - CART_X[0]), CART_Y, 0.0)


def build_patio_cart():
    """The patio (make_patio.build_patio) plus the moving Cart."""
    scene = build_patio()
    builder = MeshBuilder()
    box(builder, (0.0, 0.0, CART_SIZE[2] / 2), CART_SIZE)
    cart = add_object("Cart", builder, make_material("Cart", CART_COLOUR), cart_location(FRAME_START))
    add_lightmap_uv(cart)
    for frame in range(FRAME_START, FRAME_END + 1):
        cart.location = cart_location(frame)
        cart.keyframe_insert("location", frame=frame)
    scene.frame_start, scene.frame_end = FRAME_START, FRAME_END
    scene.render.fps = 24
    scene.frame_set(FRAME_START)
    bpy.context.view_layer.update()
    return scene


def main(argv=None):
    """Build the scene and save it to argv[0] (default: patio_cart.blend here)."""
    return generate(build_patio_cart, DEFAULT_OUTPUT, argv)


if __name__ == "__main__":
    main()
