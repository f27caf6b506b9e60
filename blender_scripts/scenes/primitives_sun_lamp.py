"""Measurement scene `primitives_sun_lamp`: the primitives of `primitives.py` (Principled
BSDFs of roughness 1) under a Sun lamp (1 degree wide, strength 3, elevation 40 deg,
azimuth -50 deg) and a constant pale-blue World: sharp shadows, and rough specular layers
lit by a lamp. One frame, 240x135.

    python blender_scripts/scenes/primitives_sun_lamp.py --save out/primitives_sun_lamp.blend
"""
from common import constant_world, parse_args, save, sun_lamp
from primitives import build_objects

if __name__ == "__main__":
    path = parse_args(__doc__).save
    build_objects()
    constant_world("pale blue", (0.25, 0.3, 0.4))
    sun_lamp(50.0, -50.0, strength=3.0, angle=1.0)
    save(path)
