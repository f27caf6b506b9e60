"""Sample scene `dunes`: a sand-dune height field around a shallow bay of water, and a
whale-like creature surfacing in it, its back above the water, swimming forward with its
tail beating (an animated Bend modifier). Lit by a procedural sky with a low sun.

    python blender_scripts/scenes/dunes.py --save out/dunes.blend

Markup read by the exporter: the terrain has `logsh_heightfield`; the whale asks for 50
blocker spheres (`logsh_spheres`); the water material is `logsh_type = water`, clear
(Transmission Weight 1, IOR 1.33: `common.water_material`).
"""
import os

import numpy as np

from common import assign, camera, empty_scene, grid_object, material, mesh_object, parse_args, save, sky_world, \
    water_material

args = parse_args(__doc__)
scene = empty_scene((1, 3))
WATER_LEVEL = 0.0


def terrain_height(x, y):
    """Dunes: crescent ridges along y, smaller ripples, and a basin around the origin."""
    ridges = 0.9 * np.sin(0.55 * x + 0.6 * np.sin(0.3 * y)) ** 2 + 0.35 * np.sin(0.9 * y + 0.4 * x)
    ripples = 0.08 * np.sin(3.1 * x + 1.7 * y)
    basin = 2.2 * np.exp(-((x - 0.5) ** 2 / 30.0 + (y - 1.0) ** 2 / 14.0))
    return ridges + ripples - basin + 0.6


axis = np.linspace(-14.0, 14.0, 97)  # the height map samples these vertices (--heightmap-size 97)
dunes = grid_object("dunes", axis, axis, terrain_height)
assign(dunes, material("sand", (0.8, 0.68, 0.5), roughness=0.9))
dunes["logsh_heightfield"] = True

water = grid_object("water", np.linspace(-7.0, 8.0, 2), np.linspace(-4.0, 6.0, 2), lambda x, y: 0 * x + WATER_LEVEL)
assign(water, water_material("water", (0.55, 0.75, 0.85)))


def whale_mesh(length=6.0, rings=40, segments=24):
    """A tapered body along +x (head at +x), flattened belly, widening into flukes at the tail."""
    vertices, faces = [], []
    t = np.linspace(0.0, 1.0, rings)
    for s in t:  # s = 0 at the tail, 1 at the head
        body = np.sin(np.pi * np.clip(s, 0.0, 1.0) ** 0.75)
        fluke = np.exp(-((s - 0.03) / 0.06) ** 2)
        width = 0.9 * body + 1.3 * fluke + 0.05
        height = 0.75 * body + 0.05 * fluke + 0.04
        x = (s - 0.5) * length
        for k in range(segments):
            a = 2.0 * np.pi * k / segments
            z = height * np.sin(a) * (0.8 if np.sin(a) < 0 else 1.0)
            vertices.append((x, width * np.cos(a), z))
    for r in range(rings - 1):
        for k in range(segments):
            a, b = r * segments + k, r * segments + (k + 1) % segments
            faces.append((a, b, b + segments, a + segments))
    tail, head = len(vertices), len(vertices) + 1
    vertices += [(-0.5 * length - 0.02, 0.0, 0.0), (0.5 * length + 0.02, 0.0, 0.0)]
    last = (rings - 1) * segments
    for k in range(segments):
        faces.append((tail, (k + 1) % segments, k))
        faces.append((head, last + k, last + (k + 1) % segments))
    return vertices, faces


whale = mesh_object("whale", *whale_mesh())
assign(whale, material("whale", (0.45, 0.5, 0.58), roughness=0.7))
whale["logsh_spheres"] = 50
whale.rotation_euler = (0.0, 0.0, np.radians(20.0))
bend = whale.modifiers.new("tail beat", "SIMPLE_DEFORM")
bend.deform_method = "BEND"
bend.deform_axis = "Y"
for frame, x, angle in [(1, -1.5, 25.0), (2, -0.8, -10.0), (3, -0.1, -30.0)]:
    whale.location = (x, 0.3 + 0.35 * x, WATER_LEVEL + 0.15)
    whale.keyframe_insert("location", frame=frame)
    bend.angle = np.radians(angle)
    bend.keyframe_insert("angle", frame=frame)

camera((5.5, -9.5, 5.0), (-0.6, 0.6, 0.0), lens=30.0)
sky_world(os.path.splitext(args.save)[0] + "_sky.exr", sun_direction=(-0.5, 0.6, 0.35))
save(args.save)
