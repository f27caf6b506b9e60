"""Measurement scene `textured`: materials as Blender users make them, for measuring the
colour passes against Cycles rendering the .blend as authored. On a checker-textured
ground stand a brick-textured cube, a sphere whose colour and roughness come from a noise
texture, a gold torus whose roughness another noise drives, a vertex-painted cone and a
glossy red sphere; every material is a Principled BSDF with no logsh markup (the
exporter's defaults decide), lit by the soft sky of `primitives.py`. One frame, 240x135.

    python blender_scripts/scenes/textured.py --save out/textured.blend
"""
import math
import os

import bpy

from common import assign, camera, empty_scene, material, parse_args, save
from primitives import rest_on_ground, soft_sky_world


def principled(name, roughness=0.5, metallic=0.0, colour=(0.8, 0.8, 0.8)):
    """`common.material` without markup, and its Principled BSDF."""
    mat = material(name, colour, roughness=roughness, metallic=metallic)
    return mat, mat.node_tree.nodes["Principled BSDF"]


def textured(name, texture_type, roughness=0.5, **inputs):
    """A Principled BSDF whose Base Color is `texture_type`'s Color output."""
    mat, node = principled(name, roughness)
    texture = mat.node_tree.nodes.new(texture_type)
    for socket, value in inputs.items():
        texture.inputs[socket].default_value = value
    mat.node_tree.links.new(texture.outputs["Color"], node.inputs["Base Color"])
    return mat


def noisy_roughness(mat, low, high, scale):
    """Drives the material's Roughness by a noise texture mapped to `low`..`high`."""
    tree = mat.node_tree
    noise = tree.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = scale
    mapped = tree.nodes.new("ShaderNodeMapRange")
    mapped.inputs["To Min"].default_value, mapped.inputs["To Max"].default_value = low, high
    tree.links.new(noise.outputs["Fac"], mapped.inputs["Value"])
    tree.links.new(mapped.outputs["Result"], tree.nodes["Principled BSDF"].inputs["Roughness"])


def build(save_path):
    empty_scene((1, 1), width=240, height=135)

    bpy.ops.mesh.primitive_plane_add(size=60, location=(0, 0, 0))
    ground = textured("checker ground", "ShaderNodeTexChecker", roughness=0.8, Scale=40.0,
                      Color1=(0.8, 0.75, 0.6, 1.0), Color2=(0.15, 0.15, 0.18, 1.0))
    assign(bpy.context.object, ground).name = "ground"

    bpy.ops.mesh.primitive_cube_add(size=1.1, location=(2.4, 1.0, 0.55), rotation=(0.0, 0.0, math.radians(30)))
    bricks = textured("bricks", "ShaderNodeTexBrick", roughness=0.7, Scale=4.0,
                      Color1=(0.65, 0.2, 0.12, 1.0), Color2=(0.5, 0.25, 0.15, 1.0), Mortar=(0.8, 0.8, 0.75, 1.0))
    assign(bpy.context.object, bricks).name = "cube"

    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.65, location=(1.2, -0.9, 0.65), segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    noise = textured("noise", "ShaderNodeTexNoise", roughness=0.45, Scale=6.0, Detail=4.0)
    noisy_roughness(noise, 0.25, 0.75, 3.0)
    assign(bpy.context.object, noise).name = "noise sphere"

    bpy.ops.mesh.primitive_torus_add(major_radius=0.8, minor_radius=0.28, major_segments=64, minor_segments=24,
                                     location=(-2.3, 0.6, 0.0), rotation=(math.radians(10), 0.0, 0.0))
    bpy.ops.object.shade_smooth()
    metal, _ = principled("gold", roughness=0.3, metallic=1.0, colour=(0.95, 0.7, 0.3))
    noisy_roughness(metal, 0.15, 0.45, 8.0)
    rest_on_ground(assign(bpy.context.object, metal)).name = "torus"

    bpy.ops.mesh.primitive_cone_add(vertices=64, radius1=0.55, depth=1.5, location=(-0.9, -1.0, 0.75))
    bpy.ops.object.shade_smooth()
    cone = bpy.context.object
    colours = cone.data.color_attributes.new("paint", "FLOAT_COLOR", "POINT")
    for vertex, value in zip(cone.data.vertices, colours.data):
        t = min(max(vertex.co.z / 1.5 + 0.5, 0.0), 1.0)  # blue at the base, yellow at the tip
        value.color = (0.15 + 0.8 * t, 0.3 + 0.55 * t, 0.85 - 0.7 * t, 1.0)
    painted, node = principled("vertex paint", roughness=0.6)
    attribute = painted.node_tree.nodes.new("ShaderNodeVertexColor")
    attribute.layer_name = "paint"
    painted.node_tree.links.new(attribute.outputs["Color"], node.inputs["Base Color"])
    assign(cone, painted).name = "cone"

    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.35, location=(3.0, -0.8, 0.35), segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    assign(bpy.context.object, principled("glossy red", roughness=0.2, colour=(0.8, 0.1, 0.08))[0]).name = "red"

    camera((0.4, -7.0, 4.8), (0.3, 0.2, 0.3), lens=35.0)
    soft_sky_world(os.path.splitext(save_path)[0] + "_sky.exr")
    save(save_path)


if __name__ == "__main__":
    build(parse_args(__doc__).save)
