"""Sample scene `wrecking_ball`: a glossy steel wrecking ball on a chain swings into a
wall of 400 cubes (diffuse in three colours, one in five glossy gold) standing on a
floor, and knocks the cubes near the impact outwards. Three frames: the ball on its way,
the ball at the wall, the cubes flying. Lit by a procedural sky.

    python blender_scripts/scenes/wrecking_ball.py --save out/wrecking_ball.blend

Each cube asks for one blocker sphere and the ball for one (`logsh_spheres`), the chain
for three: 404 blockers. The floor is flat, so it is not a blocker. The cube motion is
keyframed from a simple ballistic rule (no physics simulation, so the scene is the same
on every machine).
"""
import os

import bpy
import bmesh  # after bpy: pip's bpy module provides it
import numpy as np

from common import assign, camera, empty_scene, material, parse_args, save, sky_world

args = parse_args(__doc__)
scene = empty_scene((1, 3))

bpy.ops.mesh.primitive_plane_add(size=60, location=(0, 0, 0))
assign(bpy.context.object, material("floor", (0.55, 0.55, 0.52), roughness=0.8)).name = "floor"

CUBE = 0.5
COLUMNS, ROWS, LAYERS = 20, 10, 2
diffuse = [material(f"brick {i}", c, roughness=0.8) for i, c in
           enumerate([(0.75, 0.3, 0.2), (0.8, 0.75, 0.65), (0.3, 0.45, 0.7)])]
gold = material("gold", (0.9, 0.7, 0.3), roughness=0.35, metallic=1.0)
bpy.ops.mesh.primitive_cube_add(size=CUBE)
template = bpy.context.object.data
bpy.data.objects.remove(bpy.context.object)

IMPACT = np.array([0.0, 0.0, 1.6])  # where the ball meets the wall (its front face at y = 0)
rng = np.random.default_rng(7)
for layer in range(LAYERS):
    for row in range(ROWS):
        for column in range(COLUMNS):
            i = (layer * ROWS + row) * COLUMNS + column
            mesh = template.copy()
            obj = bpy.data.objects.new(f"cube {i:03d}", mesh)
            scene.collection.objects.link(obj)
            assign(obj, gold if rng.random() < 0.2 else diffuse[int(rng.integers(len(diffuse)))])
            obj["logsh_spheres"] = 1
            rest = np.array([(column - (COLUMNS - 1) / 2) * CUBE, (layer + 0.5) * CUBE, (row + 0.5) * CUBE])
            offset = rest - IMPACT
            distance = np.linalg.norm(offset)
            obj.location = rest
            obj.keyframe_insert("location", frame=1)
            obj.keyframe_insert("location", frame=2)
            obj.keyframe_insert("rotation_euler", frame=2)
            if distance < 1.8:  # knocked: pushed away from the impact, along +y, and falling
                speed = 2.2 * (1.8 - distance)
                push = offset / max(distance, 1e-6) * speed * 0.5 + np.array([0.0, speed, 0.0])
                moved = rest + push - np.array([0.0, 0.0, 0.25 * speed * speed * 0.2])
                moved[2] = max(moved[2], 0.5 * CUBE)
                obj.location = moved
                obj.rotation_euler = tuple(rng.uniform(-0.8, 0.8, 3))
            obj.keyframe_insert("location", frame=3)
            obj.keyframe_insert("rotation_euler", frame=3)

# The ball hangs from a pivot 7 above the impact point; the pendulum swings about x.
PIVOT = (0.0, -1.1, 8.6)
LENGTH = 7.0
pivot = bpy.data.objects.new("pivot", None)
scene.collection.objects.link(pivot)
pivot.location = PIVOT
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0, 0, -LENGTH), segments=48, ring_count=24)
bpy.ops.object.shade_smooth()
ball = assign(bpy.context.object, material("steel", (0.85, 0.85, 0.88), roughness=0.2, metallic=1.0))
ball.name, ball.parent = "wrecking ball", pivot
ball["logsh_spheres"] = 1
bpy.ops.mesh.primitive_cylinder_add(radius=0.06, depth=LENGTH - 1.0, location=(0, 0, -(LENGTH - 1.0) / 2))
chain = assign(bpy.context.object, material("chain", (0.2, 0.2, 0.2), roughness=0.5, metallic=1.0))
chain.name, chain.parent = "chain", pivot
# Cut the chain into short rings: a blocker sphere holds whole triangles, and the
# primitive's side faces run the full length.
mesh = bmesh.new()
mesh.from_mesh(chain.data)
lengthwise = [e for e in mesh.edges if abs(e.verts[0].co.z - e.verts[1].co.z) > 1e-6]
bmesh.ops.subdivide_edges(mesh, edges=lengthwise, cuts=11, use_grid_fill=True)
mesh.to_mesh(chain.data)
mesh.free()
chain["logsh_spheres"] = 3
for frame, angle in [(1, -40.0), (2, 0.0), (3, 8.0)]:
    pivot.rotation_euler = (np.radians(angle), 0.0, 0.0)
    pivot.keyframe_insert("rotation_euler", frame=frame)

camera((-9.0, -11.0, 5.5), (0.5, 0.0, 2.0), lens=32.0)
sky_world(os.path.splitext(args.save)[0] + "_sky.exr", sun_direction=(-0.3, -0.6, 0.7))
save(args.save)
