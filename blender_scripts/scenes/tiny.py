"""The smallest scene that exercises every part of the exporter, for the tests: a ground
plane, a water patch, a diffuse sphere, a glossy sphere that moves between frames 1 and
2, a camera, and a grey World (constant light). No custom properties: everything is
exported with the script's defaults.

    python blender_scripts/scenes/tiny.py --save out/tiny.blend
"""
import bpy

from common import assign, camera, empty_scene, grey_world, material, parse_args, save, water_material

args = parse_args(__doc__)
scene = empty_scene((1, 2), 64, 36)

bpy.ops.mesh.primitive_plane_add(size=20, location=(0, 0, 0))
assign(bpy.context.object, material("ground", (0.8, 0.8, 0.8)))
bpy.ops.mesh.primitive_plane_add(size=3, location=(-0.5, -2.5, 0.01))
assign(bpy.context.object, water_material("water", (0.6, 0.8, 0.9))).name = "water"

bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(-1.5, 0, 1.0), segments=32, ring_count=16)
bpy.ops.object.shade_smooth()
assign(bpy.context.object, material("clay", (0.7, 0.3, 0.2))).name = "still ball"

bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(1.0, 1.5, 0.8), segments=32, ring_count=16)
bpy.ops.object.shade_smooth()
ball = assign(bpy.context.object, material("chrome", (0.9, 0.9, 0.9), roughness=0.25, metallic=1.0))
ball.name = "moving ball"
ball.keyframe_insert("location", frame=1)
ball.location = (1.0, -1.0, 1.5)
ball.keyframe_insert("location", frame=2)

camera((0, -9, 6), (0, 0, 0.5))
grey_world(1.0)
save(args.save)
