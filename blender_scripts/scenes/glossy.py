"""Measurement scene `glossy`: glossy materials against Cycles. Four metal spheres in a
row (silver, gold, copper and steel; metallic 1, roughness 0.05, 0.15, 0.3 and 0.5, all
`phong`) and a red lacquered cube (dielectric, roughness 0.1, IOR 1.5, `phong`) stand on
a light-grey diffuse mesh plane. The only light is an equirectangular sky with sharp
features for the reflections to show: a blue-to-pale gradient above the horizon, a dim
ground below, three saturated patches (red, green, blue, radiance 1.5-1.8) and one bright
white window (10 x 20 degrees, radiance 18) at 30 degrees elevation; no sun. The camera
looks down about 22 degrees so that the spheres mirror the patches and the window. One
frame, 240x135.

    python blender_scripts/scenes/glossy.py --save out/glossy.blend

`patch_sky_world` (a gradient sky with rectangular patches) and `glossy_material` are
also used by other measurement scenes (import this module's functions; the scene itself
is only built when the file is run).
"""
import math
import os

import bpy
import numpy as np

from common import assign, camera, empty_scene, environment_world, material, parse_args, save, sky_directions


def patch_sky_world(path, patches, strength=1.0, width=1024):
    """A sky with sharp-edged features, written to `path` as an equirectangular EXR
    (Blender's orientation, as `common.sky_world`) and set as the World's Environment
    Texture: a pale horizon (0.5, 0.52, 0.55) rising to a blue zenith (0.18, 0.32, 0.65), a
    dim ground (0.08, 0.075, 0.07) below, and `patches`, each (azimuth, elevation, width,
    height, rgb) in degrees (azimuth counter-clockwise from +X, elevation above the
    horizon; width along the azimuth, height along the elevation), a rectangle of
    constant radiance `rgb` that replaces the sky under it."""
    d = sky_directions(width)
    up = np.clip(d[..., 2], 0.0, 1.0)[..., None]
    sky = (1.0 - up) * np.array([0.5, 0.52, 0.55]) + up * np.array([0.18, 0.32, 0.65])
    rgb = np.where(d[..., 2:3] >= 0.0, sky, np.array([0.08, 0.075, 0.07]))
    azimuth = np.degrees(np.arctan2(d[..., 1], d[..., 0]))
    elevation = np.degrees(np.arcsin(np.clip(d[..., 2], -1.0, 1.0)))
    for centre_azimuth, centre_elevation, w, h, colour in patches:
        off = (azimuth - centre_azimuth + 180.0) % 360.0 - 180.0
        inside = (np.abs(off) <= w / 2) & (np.abs(elevation - centre_elevation) <= h / 2)
        rgb = np.where(inside[..., None], np.array(colour, dtype=float), rgb)
    return environment_world("patch sky", path, rgb, strength)


def glossy_material(name, colour, roughness, metallic):
    """A Principled BSDF (IOR 1.5) marked `phong` explicitly."""
    return material(name, colour, roughness=roughness, metallic=metallic, logsh_type="phong")


def sphere(name, location, radius, mat):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location, segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    assign(bpy.context.object, mat).name = name
    return bpy.context.object


# the camera is at azimuth -90 degrees (-Y): the window stands behind and to the left of
# it, the patches around it, so that each shows on the camera side of the spheres
SKY_PATCHES = [
    (-108.0, 30.0, 10.0, 20.0, (18.0, 18.0, 18.0)),  # window
    (-55.0, 15.0, 25.0, 20.0, (1.6, 0.12, 0.1)),  # red
    (-140.0, 12.0, 25.0, 16.0, (0.12, 1.5, 0.15)),  # green
    (-80.0, 46.0, 25.0, 12.0, (0.15, 0.25, 1.8)),  # blue
]


def build(save_path):
    empty_scene((1, 1), width=240, height=135)

    bpy.ops.mesh.primitive_plane_add(size=60, location=(0, 0, 0))
    assign(bpy.context.object, material("floor", (0.8, 0.8, 0.8), roughness=1.0, logsh_type="diffuse")).name = "floor"

    radius = 0.6
    for i, (name, colour, roughness) in enumerate([("silver", (0.9, 0.9, 0.9), 0.05),
                                                   ("gold", (1.0, 0.78, 0.35), 0.15),
                                                   ("copper", (0.95, 0.6, 0.5), 0.3),
                                                   ("steel", (0.7, 0.72, 0.75), 0.5)]):
        sphere(name, (-2.175 + 1.45 * i, 0.0, radius), radius, glossy_material(name, colour, roughness, 1.0))

    # the lacquered cube stands behind the row, between the gold and copper spheres
    bpy.ops.mesh.primitive_cube_add(size=0.9, location=(0.0, 1.4, 0.45), rotation=(0.0, 0.0, math.radians(25)))
    assign(bpy.context.object, glossy_material("red lacquer", (0.8, 0.04, 0.03), 0.1, 0.0)).name = "cube"

    camera((0.0, -6.0, 2.9), (0.0, 0.35, 0.35), lens=38.0)
    patch_sky_world(os.path.splitext(save_path)[0] + "_sky.exr", SKY_PATCHES)
    save(save_path)


if __name__ == "__main__":
    build(parse_args(__doc__).save)
