"""Measurement scene `sun_lamp`: what a relight does to a Blender Sun lamp. A height-field
terrain of rolling hills (`logsh_heightfield`), a chrome sphere (metallic 1, roughness
0.12, `phong`) moving across it over three frames, Suzanne in red lacquer (roughness
0.15, `phong`) and a clay cube, lit by a Sun lamp (2 deg wide, strength 2, azimuth -60
deg, elevation 50 deg), a Point lamp (300 W, radius 0.2) and a 512x256 sky with three
bright patches (red, green, and a white one of radiance 8). Frames 1-3, 320x180.

    python blender_scripts/scenes/sun_lamp.py --save out/sun_lamp.blend

The README's Sun-lamp relight figures come from it (exported with export_scene.py,
measured with `relight_accuracy --rotation 75`).
"""
import math
import os

import bpy
import numpy as np

from common import assign, camera, empty_scene, grid_object, material, parse_args, save
from glossy import patch_sky_world

args = parse_args(__doc__)
empty_scene((1, 3), width=320, height=180)

axis = np.linspace(-10.0, 10.0, 81)
hills = grid_object("hills", axis, axis,
                    lambda x, y: 0.5 * np.sin(0.5 * x) * np.cos(0.4 * y) + 0.3 * np.sin(0.9 * y + 0.2 * x) + 0.8)
assign(hills, material("grass", (0.55, 0.7, 0.45), roughness=0.9))
hills["logsh_heightfield"] = True

bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(0.0, 0.0, 2.2), segments=48, ring_count=24)
bpy.ops.object.shade_smooth()
ball = bpy.context.object
assign(ball, material("chrome", (0.9, 0.9, 0.92), roughness=0.12, metallic=1.0, logsh_type="phong")).name = "ball"
for frame, x in [(1, -1.5), (2, -0.5), (3, 0.5)]:
    ball.location = (x, 0.3, 2.2)
    ball.keyframe_insert("location", frame=frame)

bpy.ops.mesh.primitive_monkey_add(size=1.4, location=(1.8, 1.5, 2.0), rotation=(0.0, 0.0, math.radians(-20)))
bpy.ops.object.shade_smooth()
assign(bpy.context.object, material("lacquer", (0.7, 0.1, 0.1), roughness=0.15, logsh_type="phong")).name = "suzanne"
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-2.5, 2.0, 1.8), rotation=(0.0, 0.0, math.radians(25)))
assign(bpy.context.object, material("clay", (0.8, 0.75, 0.6), roughness=0.8)).name = "cube"

sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
sun.data.energy = 2.0
sun.data.angle = math.radians(2.0)
sun.rotation_euler = (math.radians(40), 0.0, math.radians(30))
bpy.context.scene.collection.objects.link(sun)
lamp = bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", "POINT"))
lamp.data.energy = 300.0
lamp.data.shadow_soft_size = 0.2
lamp.location = (3.0, -2.0, 4.0)
bpy.context.scene.collection.objects.link(lamp)

camera((7.0, -9.0, 6.0), (0.0, 0.5, 1.5), lens=32.0)
patch_sky_world(os.path.splitext(args.save)[0] + "_sky.exr",
                [(60.0, 25.0, 20.0, 15.0, (1.8, 0.4, 0.3)), (-100.0, 40.0, 12.0, 25.0, (0.3, 1.5, 0.4)),
                 (170.0, 20.0, 10.0, 10.0, (8.0, 8.0, 7.0))],
                width=512)
save(args.save)
