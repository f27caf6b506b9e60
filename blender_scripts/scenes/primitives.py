"""Sample scene `primitives`: a diffuse scene of primitives and concave meshes on a ground
plane under a soft sky, for measuring blocker shadows against Cycles. A torus, Suzanne
(subdivided once), a cube, a cone and two spheres stand on a plain mesh plane (not a
height field); every material is `diffuse`; the only light is a smooth procedural sky
(brighter towards the zenith, with one broad brighter region and no sun), so every shadow
is soft. One frame, 240x135.

    python blender_scripts/scenes/primitives.py --save out/primitives.blend

`soft_sky_world` and `build_objects` (the scene without its World) are also used by other
measurement scenes (import this module's functions; the scene itself is only built when
the file is run).
"""
import math
import os

import bpy
import numpy as np

from common import assign, camera, empty_scene, environment_world, material, parse_args, save, sky_directions


def soft_sky_world(path, bright_direction=(0.5, -0.35, 0.8), strength=1.0, width=256):
    """A sky with no sharp feature, written to `path` as an equirectangular EXR (Blender's
    orientation, as `common.sky_world`) and set as the World's Environment Texture: a pale
    horizon rising smoothly to a brighter zenith, plus a broad brighter region (a Gaussian
    lobe of 0.6 rad, about 34 degrees) around `bright_direction`; a dim ground below."""
    d = sky_directions(width)
    up = np.clip(d[..., 2], 0.0, 1.0)[..., None]
    sky = (1.0 - up) * np.array([0.25, 0.26, 0.28]) + up * np.array([0.42, 0.46, 0.52])
    ground = np.array([0.1, 0.095, 0.09])
    # smooth over ~6 degrees across the horizon so that nothing in the map is sharp
    t = np.clip(d[..., 2:3] / 0.1 + 0.5, 0.0, 1.0)
    rgb = t * sky + (1.0 - t) * ground
    bright = np.array(bright_direction) / np.linalg.norm(bright_direction)
    angle = np.arccos(np.clip(d @ bright, -1.0, 1.0))
    rgb = rgb + np.exp(-(angle / 0.6) ** 2)[..., None] * np.array([1.7, 1.6, 1.4])
    return environment_world("soft sky", path, rgb, strength)


def diffuse(name, colour):
    return material(name, colour, roughness=1.0, metallic=0.0, logsh_type="diffuse")


def rest_on_ground(obj):
    """Moves `obj` along Z so that the lowest point of its evaluated (modified) mesh is at 0."""
    bpy.context.view_layer.update()
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    lowest = min((evaluated.matrix_world @ v.co).z for v in evaluated.to_mesh().vertices)
    evaluated.to_mesh_clear()
    obj.location.z -= lowest
    return obj


def build(save_path):
    build_objects()
    soft_sky_world(os.path.splitext(save_path)[0] + "_sky.exr")
    save(save_path)


def build_objects():
    """The scene without its World: primitives on a ground plane, and the camera."""
    empty_scene((1, 1), width=240, height=135)

    bpy.ops.mesh.primitive_plane_add(size=60, location=(0, 0, 0))
    assign(bpy.context.object, diffuse("ground", (0.8, 0.8, 0.8))).name = "ground"

    # a torus lying almost flat (tilted 10 degrees about X), touching the ground
    bpy.ops.mesh.primitive_torus_add(major_radius=0.8, minor_radius=0.28, major_segments=64, minor_segments=24,
                                     location=(-2.3, 0.6, 0.0), rotation=(math.radians(10), 0.0, 0.0))
    bpy.ops.object.shade_smooth()
    rest_on_ground(assign(bpy.context.object, diffuse("pink", (0.9, 0.6, 0.65)))).name = "torus"

    # Suzanne, subdivided once, upright on her chin, turned towards the camera
    bpy.ops.mesh.primitive_monkey_add(size=1.6, location=(0.0, 1.4, 0.0), rotation=(0.0, 0.0, math.radians(-15)))
    suzanne = bpy.context.object
    suzanne.modifiers.new("subdivision", "SUBSURF").levels = 1
    suzanne.modifiers["subdivision"].render_levels = 1
    bpy.ops.object.shade_smooth()
    rest_on_ground(assign(suzanne, diffuse("mint", (0.6, 0.85, 0.7)))).name = "suzanne"

    # a cube turned 30 degrees about Z
    bpy.ops.mesh.primitive_cube_add(size=1.1, location=(2.4, 1.0, 0.55), rotation=(0.0, 0.0, math.radians(30)))
    assign(bpy.context.object, diffuse("sky blue", (0.6, 0.72, 0.9))).name = "cube"

    bpy.ops.mesh.primitive_cone_add(vertices=64, radius1=0.55, depth=1.5, location=(-0.9, -1.0, 0.75))
    bpy.ops.object.shade_smooth()
    assign(bpy.context.object, diffuse("butter", (0.92, 0.85, 0.55))).name = "cone"

    for name, (x, y), radius, colour in [("big sphere", (1.2, -0.9), 0.65, (0.78, 0.65, 0.9)),
                                         ("small sphere", (3.0, -0.8), 0.35, (0.95, 0.72, 0.5))]:
        bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=(x, y, radius), segments=48, ring_count=24)
        bpy.ops.object.shade_smooth()
        assign(bpy.context.object, diffuse(name, colour)).name = name

    camera((0.4, -7.0, 4.8), (0.3, 0.2, 0.3), lens=35.0)


if __name__ == "__main__":
    build(parse_args(__doc__).save)
