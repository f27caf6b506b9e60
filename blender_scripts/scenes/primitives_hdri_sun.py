"""Measurement scene `primitives_hdri_sun`: the primitives of `primitives.py` (Principled
BSDFs of roughness 1) under an equirectangular sky with a sun in it: `primitives`' soft
sky at 2048x1024, plus a disk of 0.5 degree (irradiance 3 at normal incidence, elevation
35 deg), which `--sharp-lights auto` takes out of the map as a sun. One frame, 240x135.

    python blender_scripts/scenes/primitives_hdri_sun.py --save out/primitives_hdri_sun.blend
"""
import math
import os

import numpy as np

from common import environment_world, parse_args, save, sky_directions
from primitives import build_objects

SUN_DIRECTION = (math.cos(math.radians(35)) * math.cos(math.radians(-40)),
                 math.cos(math.radians(35)) * math.sin(math.radians(-40)), math.sin(math.radians(35)))
SUN_RADIUS = math.radians(0.25)
SUN_IRRADIANCE = 3.0


def hdri_sun_world(path, width=2048):
    d = sky_directions(width)
    up = np.clip(d[..., 2], 0.0, 1.0)[..., None]
    sky = (1.0 - up) * np.array([0.25, 0.26, 0.28]) + up * np.array([0.42, 0.46, 0.52])
    t = np.clip(d[..., 2:3] / 0.1 + 0.5, 0.0, 1.0)
    rgb = t * sky + (1.0 - t) * np.array([0.1, 0.095, 0.09])
    sun = np.array(SUN_DIRECTION)
    inside = np.arccos(np.clip(d @ sun, -1.0, 1.0)) <= SUN_RADIUS
    # The disk's texels share the irradiance by their solid angles.
    height = width // 2
    solid_angles = (2.0 * math.pi / width) * (math.pi / height) * np.sin((np.arange(height) + 0.5) / height * math.pi)
    disk = (inside * solid_angles[:, None]).sum()
    rgb = rgb + inside[..., None] * (SUN_IRRADIANCE / max(disk, 1e-12)) * np.array([1.0, 0.95, 0.85])
    return environment_world("sky with a sun", path, rgb, 1.0)


if __name__ == "__main__":
    path = parse_args(__doc__).save
    build_objects()
    hdri_sun_world(os.path.splitext(path)[0] + "_sky.exr")
    save(path)
