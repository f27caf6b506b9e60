"""Sample scene `swell`: an open sea as a height-field terrain, an opaque blue-green
surface (not water: a Principled BSDF 0.10, 0.30, 0.35, roughness 0.8) about 30 m
square, heaving with a travelling swell (wavelength 6 m, amplitude 0.5 m, crests
sharpened by a second harmonic, and a smaller cross wave). Its heights are shape keys: a
flat Basis and one key per frame, each key's value keyframed 1 on its frame and 0 on the
others (constant interpolation), the crests moving a third of a wavelength per frame.
Two orange-red buoys (radius 0.45 m, roughness 0.6) float on it, bobbing with the
surface under them and drifting a little. Lit by a low Sun lamp (elevation 15 deg,
strength 4, 0.5 deg wide) raking across the crests from the camera's left, so that the
lee slopes and the troughs behind the crests lie in shadow, and by a constant pale blue
World (strength 0.3). The static camera looks over the swell from 4 m up, with a thin
strip of sky at the top. Frames 1-3, 240x135.

    python blender_scripts/scenes/swell.py --save out/swell.blend

Markup read by the exporter: the sea has `logsh_heightfield` (its evaluated, shape-keyed
mesh is the height field of each frame); each buoy asks for 1 blocker sphere
(`logsh_spheres`). Materials are Principled BSDFs, typed by the exporter's defaults.
"""
import math

import bpy
import numpy as np
from bpy_extras import anim_utils

from common import assign, camera, constant_world, empty_scene, grid_object, material, parse_args, save, sun_lamp

args = parse_args(__doc__)
empty_scene((1, 3), width=240, height=135)
FRAMES = (1, 2, 3)

WAVELENGTH = 6.0  # the swell (m)
AMPLITUDE = 0.5  # of its first harmonic (m)
HEADING = math.radians(30.0)  # the swell travels along (cos, sin) of this
CROSS_WAVELENGTH, CROSS_AMPLITUDE, CROSS_HEADING = 3.0, 0.1, math.radians(-50.0)


def sea_height(x, y, frame):
    """The swell at `frame`: a Stokes-like wave (crests sharper, troughs flatter) whose
    amplitude swells and fades a little along its crests, moving a third of a wavelength
    per frame, plus a cross wave moving a quarter of its wavelength per frame."""
    k = 2.0 * np.pi / WAVELENGTH
    along = np.cos(HEADING) * x + np.sin(HEADING) * y
    across = -np.sin(HEADING) * x + np.cos(HEADING) * y
    amplitude = AMPLITUDE * (1.0 + 0.2 * np.sin(0.15 * across + 0.8))
    phase = k * along - 2.0 * np.pi / 3.0 * (frame - 1)
    swell = amplitude * np.cos(phase) + 0.5 * k * amplitude ** 2 * np.cos(2.0 * phase)
    k2 = 2.0 * np.pi / CROSS_WAVELENGTH
    cross_phase = k2 * (np.cos(CROSS_HEADING) * x + np.sin(CROSS_HEADING) * y) - 0.5 * np.pi * (frame - 1)
    return swell + CROSS_AMPLITUDE * np.cos(cross_phase)


axis = np.linspace(-15.0, 15.0, 151)  # 0.2 m
sea = grid_object("sea", axis, axis, lambda x, y: 0.0 * x)  # the Basis: the calm sea
assign(sea, material("sea", (0.10, 0.30, 0.35), roughness=0.8))
sea["logsh_heightfield"] = True

sea.shape_key_add(name="Basis", from_mix=False)
gx, gy = np.meshgrid(axis, axis)  # the vertex order of grid_object
for frame in FRAMES:
    key = sea.shape_key_add(name=f"frame {frame}", from_mix=False)
    key.points.foreach_set("co", np.stack([gx, gy, sea_height(gx, gy, frame)], axis=-1).ravel())
    for keyed in FRAMES:
        key.value = 1.0 if keyed == frame else 0.0
        key.keyframe_insert("value", frame=keyed)
shape_keys = sea.data.shape_keys
channels = anim_utils.action_get_channelbag_for_slot(shape_keys.animation_data.action,
                                                     shape_keys.animation_data.action_slot)
for curve in channels.fcurves:
    for point in curve.keyframe_points:
        point.interpolation = "CONSTANT"

RADIUS = 0.45
buoy_paint = material("buoy", (0.85, 0.22, 0.08), roughness=0.6)
for i, (start, drift) in enumerate([((-1.5, -4.0), (0.12, 0.08)), ((1.5, 3.0), (-0.08, 0.12))]):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=RADIUS, segments=32, ring_count=16)
    bpy.ops.object.shade_smooth()
    buoy = assign(bpy.context.object, buoy_paint)
    buoy.name = f"buoy {i}"
    buoy["logsh_spheres"] = 1
    for frame in FRAMES:
        x, y = start[0] + drift[0] * (frame - 1), start[1] + drift[1] * (frame - 1)
        # floating with a little under a third of its height below the surface
        buoy.location = (x, y, float(sea_height(x, y, frame)) + 0.4 * RADIUS)
        buoy.keyframe_insert("location", frame=frame)

# elevation 15 deg, the light heading along (cos 20 deg, sin 20 deg), 10 deg off the
# swell's heading: from the camera's left and a little behind it, across the crests
sun_lamp(75.0, -70.0)
constant_world("pale blue", (0.6, 0.75, 1.0), 0.3)

camera((0.0, -13.5, 4.0), (0.0, -3.9, 0.0), lens=35.0)
save(args.save)
