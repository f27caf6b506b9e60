"""Sample scene `canyon`: a sandstone canyon, a winding valley about 3.6 m deep between
steep walls (up to about 75 degrees), as a height-field terrain, with four squashed
boulders of grey stone on its sandy floor. Lit by a low Sun lamp (elevation 22 deg,
strength 4, 0.5 deg wide) raking across the valley from behind the camera's left, so
that the left-hand wall and part of the floor lie in shadow (lit by the sky and by
light bounced off the sunlit wall), and by a constant pale blue World (strength 0.3).
The camera looks down the valley from above its floor: both walls and the floor fill
the frame, with two slivers of sky at the top. One frame, 240x135.

    python blender_scripts/scenes/canyon.py --save out/canyon.blend

Markup read by the exporter: the terrain has `logsh_heightfield`; each boulder asks for
4 blocker spheres (`logsh_spheres`). Materials are Principled BSDFs (sandstone 0.75,
0.45, 0.28 and stone 0.5 grey, roughness 0.9), typed by the exporter's defaults.
"""
import math

import bpy
import numpy as np

from common import assign, camera, constant_world, empty_scene, grid_object, material, parse_args, save, sun_lamp

args = parse_args(__doc__)
empty_scene((1, 1), width=240, height=135)

DEPTH = 3.6  # rim above the valley floor (m)
WALL = 1.4  # horizontal run of a wall (m): slopes up to 1.5 * DEPTH / WALL, about 75 degrees


def centre(y):
    """The valley's centre line: it winds left and right as it runs along +y."""
    return 2.6 * np.sin(0.2 * y) + 0.6 * np.sin(0.5 * y + 1.0)


def floor_height(x, y):
    """Sand ripples on the valley floor."""
    return 0.08 * np.sin(0.7 * x + 0.4 * y) + 0.05 * np.sin(1.3 * y)


def canyon_height(x, y):
    """Floor, then a smoothstep wall up to the rim, then an undulating plateau."""
    half_width = 2.8 + 0.5 * np.sin(0.3 * y + 0.5)
    t = np.clip((np.abs(x - centre(y)) - half_width) / WALL, 0.0, 1.0)
    wall = t * t * (3.0 - 2.0 * t)
    plateau = 0.3 * np.sin(0.4 * x + 0.7) * np.cos(0.3 * y) + 0.15 * np.sin(0.9 * x - 0.6 * y)
    ledge = 0.12 * np.sin(np.pi * 3.0 * wall)  # a faint banding of the strata on the walls
    return (1.0 - wall) * floor_height(x, y) + wall * (DEPTH + t * plateau) + ledge


xs = np.linspace(-14.0, 14.0, 141)  # 0.2 m, about the height map's spacing (256 along y)
ys = np.linspace(-12.0, 36.0, 241)
canyon = grid_object("canyon", xs, ys, canyon_height)
assign(canyon, material("sandstone", (0.75, 0.45, 0.28), roughness=0.9))
canyon["logsh_heightfield"] = True

stone = material("stone", (0.5, 0.5, 0.5), roughness=0.9)
for i, (y, offset, radius, squash, turn) in enumerate([(-1.5, 1.1, 0.55, 0.65, 10.0), (2.5, -1.3, 0.8, 0.6, 40.0),
                                                       (6.5, 0.9, 0.45, 0.7, -25.0), (10.0, -0.2, 0.7, 0.55, 70.0)]):
    x = float(centre(y)) + offset
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=radius)
    bpy.ops.object.shade_smooth()
    boulder = assign(bpy.context.object, stone)
    boulder.name = f"boulder {i}"
    boulder.scale = (1.0, 0.85, squash)
    boulder.rotation_euler = (0.0, 0.0, math.radians(turn))
    # sunk a tenth of its height into the sand
    boulder.location = (x, y, float(floor_height(x, y)) + 0.8 * radius * squash)
    boulder["logsh_spheres"] = 4

# elevation 22 deg, the sun to the left of and behind the camera, 35 deg off the valley's
# axis (+y)
sun_lamp(68.0, -35.0)
constant_world("pale blue", (0.6, 0.75, 1.0), 0.3)

camera((float(centre(-9.0)), -9.0, 5.0), (float(centre(3.0)), 3.0, 0.0), lens=30.0)
save(args.save)
