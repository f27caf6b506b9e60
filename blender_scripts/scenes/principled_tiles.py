"""Measurement scene `principled_tiles`: how a Sun lamp reflects off Principled BSDFs, with
nothing else in the way. Four flat tiles side by side, each a Principled BSDF: three
dielectrics (base colour 0.8, IOR 1.5) of roughness 0.3, 0.6 and 1.0 and a metal (base
colour 0.9, roughness 0.6), lit by a Sun lamp (0.5 degree wide, strength 3, elevation 40
deg, from behind the tiles on the left) under a black World, seen from above at about 25
deg. No blocker, no bounce between the tiles: the frame is the BSDF under one lamp. One
frame, 240x135.

    python blender_scripts/scenes/principled_tiles.py --save out/principled_tiles.blend
"""
import bpy

from common import assign, camera, constant_world, empty_scene, material, parse_args, save, sun_lamp

TILES = [("rough 0.3", (0.8, 0.8, 0.8), 0.3, 0.0), ("rough 0.6", (0.8, 0.8, 0.8), 0.6, 0.0),
         ("rough 1.0", (0.8, 0.8, 0.8), 1.0, 0.0), ("metal 0.6", (0.9, 0.9, 0.9), 0.6, 1.0)]

if __name__ == "__main__":
    path = parse_args(__doc__).save
    empty_scene((1, 1), width=240, height=135)
    for k, (name, colour, roughness, metallic) in enumerate(TILES):
        bpy.ops.mesh.primitive_plane_add(size=3.0, location=(-4.65 + 3.1 * k, 0.0, 0.0))
        tile = assign(bpy.context.object, material(name, colour, roughness=roughness, metallic=metallic))
        tile.name = name
        tile["logsh_spheres"] = 0
    constant_world("black", (0.0, 0.0, 0.0))
    sun_lamp(50.0, 200.0, strength=3.0, angle=0.5)
    camera((0.0, -9.0, 4.2), (0.0, 0.0, 0.0), lens=35.0)
    save(path)
