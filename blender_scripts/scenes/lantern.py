"""Sample scene `lantern`: a lantern carried low along a valley at night. The valley is a
height-field terrain of grey sand (0.55, 0.5, 0.42, roughness 0.9) about 20 m square: a
winding floor about 2.6 m wide between slopes of 25 to 45 degrees that rise 2.5 m to
either side, then a gently undulating upland. The lantern is a warm Point lamp (150 W,
radius 0.1 m, colour 1.0, 0.8, 0.55) 0.6 m above the floor directly below it, carried
1.5 m along the valley each frame: it lies below the horizontal plane of most of the
slope it lights, so a receiver must see a lamp beneath its own horizon. The night is a
constant dark blue World (strength 0.02), no sun. The static camera looks down the
valley from above and behind the lantern: both slopes and the floor around it fill the
frame. Frames 1-3, 240x135.

    python blender_scripts/scenes/lantern.py --save out/lantern.blend

Markup read by the exporter: the terrain has `logsh_heightfield`. Its material is a
Principled BSDF, typed by the exporter's defaults.
"""

import bpy
import numpy as np

from common import assign, camera, constant_world, empty_scene, grid_object, material, parse_args, save

args = parse_args(__doc__)
empty_scene((1, 3), width=240, height=135)

DEPTH = 2.5  # the slopes' rise from the floor to the upland (m)
SOFT = 0.12  # the rounding of a slope's foot and brow, as a fraction of its run


def centre(y):
    """The valley's centre line: it winds left and right as it runs along +y."""
    return 1.2 * np.sin(0.25 * y + 0.3) + 0.3 * np.sin(0.55 * y)


def floor_height(x, y):
    """Faint ripples on the valley floor."""
    return 0.04 * np.sin(0.9 * x + 0.5 * y) + 0.03 * np.sin(1.4 * y + 0.3)


def valley_height(x, y):
    """Floor, then a straight slope (its foot and brow rounded) up to an undulating upland.
    The slope's angle varies along the valley, and differs from the left side to the
    right: 26 to 38 degrees across the contours, steepened a little where the valley
    winds, so 25 to 45 degrees down the fall line."""
    offset = x - centre(y)
    half_width = 1.3 + 0.3 * np.sin(0.35 * y + 1.0)
    angle = np.where(offset < 0.0, 32.0 + 6.0 * np.sin(0.3 * y + 0.5), 31.0 + 5.0 * np.sin(0.25 * y - 1.0))
    run = DEPTH / np.tan(np.radians(angle))
    t = (np.abs(offset) - half_width) / run

    def softplus(s):
        return SOFT * np.logaddexp(0.0, s / SOFT)

    rise = (softplus(t) - softplus(t - 1.0)) / (softplus(1.0) - softplus(0.0))
    upland = 0.2 * np.sin(0.45 * x + 0.4) * np.cos(0.35 * y) + 0.08 * np.sin(0.8 * x - 0.6 * y)
    gullies = 0.05 * np.sin(1.7 * y + 0.6 * x) * np.sin(np.pi * np.clip(t, 0.0, 1.0))
    return (1.0 - rise) * floor_height(x, y) + rise * (DEPTH + upland) + gullies


xs = np.linspace(-10.0, 10.0, 135)  # 0.15 m
ys = np.linspace(-8.0, 12.0, 135)
valley = grid_object("valley", xs, ys, valley_height)
assign(valley, material("sand", (0.55, 0.5, 0.42), roughness=0.9))
valley["logsh_heightfield"] = True

lantern = bpy.data.objects.new("lantern", bpy.data.lights.new("lantern", "POINT"))
lantern.data.energy = 150.0
lantern.data.shadow_soft_size = 0.1
lantern.data.color = (1.0, 0.8, 0.55)
bpy.context.scene.collection.objects.link(lantern)
for frame, y in [(1, -1.5), (2, 0.0), (3, 1.5)]:
    x = float(centre(y))
    lantern.location = (x, y, float(valley_height(x, y)) + 0.6)
    lantern.keyframe_insert("location", frame=frame)

constant_world("night", (0.25, 0.35, 0.7), 0.02)

camera((float(centre(-6.5)), -6.5, 3.2), (float(centre(0.5)), 0.5, 0.4), lens=24.0)
save(args.save)
