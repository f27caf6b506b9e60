"""Sample scene `cones`: cones and spheres on a plane, diffuse and glossy, one sphere
rolling between the two frames, under a procedural sky. Nothing is marked up: it is
exported with the exporter's defaults (8 spheres per object, materials typed by
roughness and metallic, the flat ground left out of the blockers).

    python blender_scripts/scenes/cones.py --save out/cones.blend
"""
import os

import bpy

from common import assign, camera, empty_scene, material, parse_args, save, sky_world

args = parse_args(__doc__)
scene = empty_scene((1, 2))

bpy.ops.mesh.primitive_plane_add(size=40, location=(0, 0, 0))
assign(bpy.context.object, material("ground", (0.7, 0.7, 0.7), roughness=0.9)).name = "ground"

materials = {
    "chalk": material("chalk", (0.85, 0.85, 0.8), roughness=0.8),
    "terracotta": material("terracotta", (0.75, 0.35, 0.2), roughness=0.7),
    "lacquer": material("lacquer", (0.1, 0.25, 0.6), roughness=0.3),
    "copper": material("copper", (0.95, 0.6, 0.45), roughness=0.3, metallic=1.0),
}
for i, (x, y, radius, depth, m) in enumerate([(-3.0, 1.0, 1.0, 2.6, "chalk"), (0.5, 2.5, 0.8, 3.2, "terracotta"),
                                              (3.2, 0.2, 1.1, 2.2, "copper"), (-0.8, -1.5, 0.6, 1.6, "lacquer")]):
    bpy.ops.mesh.primitive_cone_add(vertices=48, radius1=radius, depth=depth, location=(x, y, depth / 2))
    bpy.ops.object.shade_smooth()
    assign(bpy.context.object, materials[m]).name = f"cone {i}"

for i, (location, radius, m) in enumerate([((-1.2, 3.8, 0.9), 0.9, "copper"), ((2.0, -2.2, 0.7), 0.7, "chalk"),
                                           ((4.6, 3.0, 1.2), 1.2, "lacquer")]):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location, segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    assign(bpy.context.object, materials[m]).name = f"sphere {i}"

bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(-3.5, -2.0, 0.8), segments=48, ring_count=24)
bpy.ops.object.shade_smooth()
rolling = assign(bpy.context.object, materials["terracotta"])
rolling.name = "rolling sphere"
rolling.keyframe_insert("location", frame=1)
rolling.location = (-1.9, -2.6, 0.8)
rolling.keyframe_insert("location", frame=2)

camera((2.0, -12.0, 6.0), (0.4, 0.8, 0.8), lens=35.0)
sky_world(os.path.splitext(args.save)[0] + "_sky.exr", sun_direction=(0.6, -0.4, 0.55))
save(args.save)
