"""Measurement scene `sky_texture`: the primitives of `primitives.py` under Blender's Sky
Texture (its default multiple-scattering sky, Sun Elevation 25 degrees, Sun Rotation 40
degrees, Background Strength 0.1), which the exporter bakes into a map and whose sun disc
it exports as a sun light. One frame, 240x135.

    python blender_scripts/scenes/sky_texture.py --save out/sky_texture.blend
"""
import math

import bpy

from common import parse_args, save
from primitives import build_objects


def sky_texture_world(elevation, rotation, strength):
    world = bpy.data.worlds.new("sky texture")
    bpy.context.scene.world = world
    world.use_nodes = True
    nodes = world.node_tree.nodes
    sky = nodes.new("ShaderNodeTexSky")
    sky.sun_elevation, sky.sun_rotation = math.radians(elevation), math.radians(rotation)
    world.node_tree.links.new(sky.outputs["Color"], nodes["Background"].inputs["Color"])
    nodes["Background"].inputs["Strength"].default_value = strength
    return world


if __name__ == "__main__":
    path = parse_args(__doc__).save
    build_objects()
    sky_texture_world(25.0, 40.0, 0.1)
    save(path)
