"""What every part of the exporter shares: the object and material types it knows, the
limits of its conversions, its error, and the writers of its files."""

import json
import os


GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES"}
MATERIAL_TYPES = ("diffuse", "phong", "water", "heightfield")
# The narrowest pixel filter Cycles accepts: every sample lands within about 0.01 px of
# the centre. Not a box: Cycles' box filter is one pixel wide whatever its width (a
# 1024-sample render with a 0.01 px box averaged each pixel over its whole area).
DATA_FILTER, DATA_FILTER_WIDTH = "GAUSSIAN", 0.01
FLAT_THICKNESS = 0.02
# Roughness 0.027 (module doc): sharper than any environment map resolves.
MAX_EXPONENT = 1.0e6
# Roughness 1 (module doc): GGX alpha 0.99.
MIN_EXPONENT = 0.01
VIEW_LAYER = "ViewLayer"
MAX_SUPERSAMPLE = 4
# A Principled BSDF's Transmission, Subsurface, Sheen or Coat weight up to which it is
# left out without a word (a weight of 0.01 moves a pixel by about 1 %).
NEGLIGIBLE_WEIGHT = 0.01
SURFACE_NODES = ("BSDF_PRINCIPLED", "BSDF_DIFFUSE", "BSDF_GLOSSY", "BSDF_ANISOTROPIC")




class ExportError(Exception):
    """Something the exporter cannot write; the message says what and how to fix it."""


def new_file(out, name):
    """The path of output `name`, which must not exist yet: an export never writes over a
    file, so neither an earlier export nor an input (the .blend, an image) is lost."""
    path = os.path.join(out, name)
    if os.path.exists(path):
        raise ExportError(f"{path} exists; export into an empty directory")
    return path


def write_blockers(path, frame, spheres, sun_shadows=None):
    """One sphere per line: hundreds of blockers stay small and readable. `sun_shadows`,
    when there are any, one line each after them."""
    lines = ",\n".join("  " + json.dumps(s) for s in spheres)
    shadows = ""
    if sun_shadows:
        shadows = ', "sun_shadows": [\n' + ",\n".join("  " + json.dumps(s) for s in sun_shadows) + "\n]"
    with open(path, "w") as f:
        f.write(f'{{"frame": {frame}, "spheres": [\n{lines}\n]{shadows}}}\n')


def write_json(path, value):
    with open(path, "w") as f:
        json.dump(value, f, indent=1)
        f.write("\n")
