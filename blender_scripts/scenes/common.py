"""Helpers shared by the scene builders: an empty scene, materials with logsh markup, a
camera aimed at a point, a procedural sky written as an equirectangular EXR, and the
command line every builder takes (`--save FILE.blend`, after `--` under `blender -b`).

Nothing is downloaded: every mesh and image is made here.
"""
import argparse
import math
import os
import sys

import bpy
import mathutils
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from logsh_exporter.exr import write_exr  # noqa: E402


def parse_args(description):
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--save", required=True, help="the .blend to write (must not exist)")
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    args = parser.parse_args(argv)
    args.save = os.path.abspath(args.save)
    if os.path.exists(args.save):
        sys.exit(f"error: {args.save} exists; builders never write over a file")
    os.makedirs(os.path.dirname(args.save), exist_ok=True)
    return args


def empty_scene(frames, width=480, height=270):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.frame_start, scene.frame_end = frames
    scene.view_settings.view_transform = "Standard"
    return scene


def material(name, colour, roughness=0.5, metallic=0.0, logsh_type=None):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    m.diffuse_color = (*colour, 1.0)
    if logsh_type:
        m["logsh_type"] = logsh_type
    return m


def water_material(name, colour):
    """Water as Blender users make it: a clear Principled BSDF (Transmission Weight 1, IOR
    1.33, roughness 0) marked `logsh_type = water`, whose Fresnel reflection logsh shades
    through the reflection G-buffer; `colour` is its tint without colour passes."""
    m = material(name, colour, roughness=0.0, logsh_type="water")
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["IOR"].default_value = 1.33
    return m


def assign(obj, mat):
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    return obj


def mesh_object(name, vertices, faces, smooth=True):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(map(float, v)) for v in vertices], [], [tuple(map(int, f)) for f in faces])
    mesh.update()
    if smooth:
        mesh.shade_smooth()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def grid_object(name, xs, ys, height_fn, smooth=True):
    """A grid mesh over xs x ys with z = height_fn(x, y)."""
    gx, gy = np.meshgrid(xs, ys)
    vertices = np.stack([gx, gy, height_fn(gx, gy)], axis=-1).reshape(-1, 3)
    nx = len(xs)
    faces = [(j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i)
             for j in range(len(ys) - 1) for i in range(nx - 1)]
    return mesh_object(name, vertices, faces, smooth)


def camera(location, target, lens=35.0):
    data = bpy.data.cameras.new("camera")
    data.lens = lens
    obj = bpy.data.objects.new("camera", data)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj
    obj.location = location
    direction = mathutils.Vector(target) - mathutils.Vector(location)
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    return obj


def sky_directions(width):
    """The unit direction of every texel of a `width` x `width / 2` equirectangular map in
    Blender's orientation (first row the zenith, the centre column +X), (rows, columns, 3)."""
    height = width // 2
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.arange(height) + 0.5) / height
    phi = -2.0 * np.pi * u[None, :] + np.pi
    theta = -np.pi * v[:, None] + np.pi
    return np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)), axis=-1)


def environment_world(name, path, rgb, strength):
    """Writes `rgb` (rows, columns, 3) to `path` as an EXR and makes it the World's
    Environment Texture at `strength`."""
    write_exr(path, {c: rgb[..., k] for k, c in enumerate("RGB")})
    world = bpy.data.worlds.new(name)
    world.use_nodes = True
    nodes = world.node_tree.nodes
    texture = nodes.new("ShaderNodeTexEnvironment")
    texture.image = bpy.data.images.load(path)
    background = nodes["Background"]
    background.inputs["Strength"].default_value = strength
    world.node_tree.links.new(texture.outputs["Color"], background.inputs["Color"])
    bpy.context.scene.world = world
    return world


def sky_world(path, sun_direction=(0.4, -0.3, 0.6), strength=1.0, width=256):
    """A procedural sky (zenith blue to a pale horizon, a dim ground, a soft sun) written
    to `path` as an equirectangular EXR in Blender's orientation (first row the zenith,
    the centre column +X) and set as the World's Environment Texture."""
    d = sky_directions(width)
    up = np.clip(d[..., 2], 0.0, 1.0)[..., None]
    sky = (1.0 - up) * np.array([0.95, 0.95, 0.9]) + up * np.array([0.35, 0.55, 0.95])
    ground = np.array([0.25, 0.22, 0.2])
    rgb = np.where(d[..., 2:3] >= 0.0, sky, ground)
    sun = np.array(sun_direction) / np.linalg.norm(sun_direction)
    angle = np.arccos(np.clip(d @ sun, -1.0, 1.0))
    rgb = rgb + np.exp(-(angle / 0.12) ** 2)[..., None] * np.array([6.0, 5.5, 4.5])
    return environment_world("sky", path, rgb, strength)


def constant_world(name, colour, strength=1.0):
    """The scene's World: one colour times `strength`."""
    world = bpy.data.worlds.new(name)
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (*colour, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = strength
    bpy.context.scene.world = world
    return world


def grey_world(value=1.0):
    return constant_world("grey", (value, value, value))


def sun_lamp(tilt, turn, strength=4.0, angle=0.5):
    """A Sun lamp whose light travels along its -Z, tilted `tilt` degrees from the zenith
    (the sun's elevation is 90 - `tilt`) and turned `turn` degrees about Z; `angle` is
    its disk's diameter in degrees."""
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = strength
    sun.data.angle = math.radians(angle)
    sun.rotation_euler = (math.radians(tilt), 0.0, math.radians(turn))
    bpy.context.scene.collection.objects.link(sun)
    return sun


def save(path):
    bpy.ops.wm.save_as_mainfile(filepath=path, check_existing=False)
    print(f"wrote {path}")
