"""Exports a Blender scene as a logsh scene (format v1): G-buffers, reflection G-buffer,
per-frame sphere blockers and camera, height map, materials and the World's light.

    blender -b scene.blend -P blender_scripts/export_scene.py -- --out DIR [--frames 1-24]
    python blender_scripts/export_scene.py --blend scene.blend --out DIR [--frames 1-24]

(the second with Blender as a Python module: `python -m pip install bpy`). Options:

    --blend FILE            the .blend to open (required unless Blender already opened one)
    --out DIR               output directory; must not already hold a scene.json
    --frames SPEC           frames to export, as logsh render reads them: 7, 1-24, 1..24,
                            1-240x2, 1,5,10-20 (default: the scene's range)
    --resolution WxH        output size in pixels (default: the scene's, with its percentage)
    --spheres N             most blocker spheres per object without a logsh_spheres property (16)
    --fit-error E           relative volume error at which an object's fit stops adding spheres (0.1)
    --heightfield NAME      the terrain object (default: the one with logsh_heightfield set)
    --heightmap-size N      height map samples along the terrain's longer side (256)
    --supersample N         G-buffer samples per pixel along each axis, 1 to 4 (1): the
                            G-buffers at N times the output size, which logsh resolves
    --no-colour-passes      leave out the Diffuse Color and Glossy Color passes: logsh then
                            shades the material table's colours (the converted materials
                            of render_cycles.py's direct-light truth)
    --approximate           export materials logsh cannot represent (transmission,
                            subsurface, emission, another shader) with a warning each,
                            where the export otherwise stops naming the material
    --sun-shadow-resolution N
                            texels along the longer side of each sun's shadow map of the
                            blockers, 64 to 8192, or 0 for none (1024)

What is exported and how materials and blockers are derived is documented at the top of
`blender_scripts/logsh_exporter/exporter.py`; the add-on in the same folder runs the same
code from Blender's File > Export menu. Exits with status 1 and one `error:` line when the
scene cannot be exported. The .blend is never written.
"""
import argparse
import os
import re
import sys

try:
    import bpy
except ImportError:
    sys.exit(f"error: {sys.executable} has no bpy (Blender as a Python module). Run `bash .ci/bpy-setup` and use "
             ".venv-bpy/bin/python (pip's bpy), or run this script inside Blender: "
             "blender -b scene.blend -P blender_scripts/export_scene.py -- --out DIR")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from logsh_exporter.exporter import ExportError, Options, export  # noqa: E402


# As `logsh render --frames` (src/render/frames.rs's MAX_FRAMES): a typo such as
# 1-1000000000 is refused.
MAX_FRAMES = 1_000_000
FRAME_ITEM = re.compile(r"^(-?\d+)(?:(?:\.\.|-)(-?\d+)(?:[x:](\d+))?)?$")


def frame_range(text):
    """The frames of a spec as `logsh render --frames` reads it (src/render/frames.rs):
    `7`, `1-24`, `1..24`, `1-240x2` or `1-240:2` (every second frame), `24-1` (counting
    down), negative frames (`-5--1`), and comma-separated lists of those; returns the
    sorted distinct frames."""
    frames = set()
    for part in text.split(","):
        item = "".join(part.split())
        match = FRAME_ITEM.match(item)
        if match is None:
            raise argparse.ArgumentTypeError(
                f"\"{part.strip()}\" is not a frame spec like 7, 1-24, 1..24, 1-240x2 or 1,5,10-20")
        first, last, step = match.groups()
        first = int(first)
        last = first if last is None else int(last)
        step = 1 if step is None else int(step)
        if step < 1:
            raise argparse.ArgumentTypeError(f"\"{part.strip()}\": the step must be at least 1")
        if abs(last - first) // step + 1 + len(frames) > MAX_FRAMES:
            raise argparse.ArgumentTypeError(f"\"{text}\": more than {MAX_FRAMES} frames")
        frames.update(range(first, last + 1, step) if last >= first else range(first, last - 1, -step))
    return sorted(frames)


def size(text):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"\"{text}\" is not a size like 480x270")
    if w <= 0 or h <= 0:
        raise argparse.ArgumentTypeError(f"size {text} is empty")
    return w, h


def main(argv):
    parser = argparse.ArgumentParser(prog="export_scene.py", description="Export a Blender scene for logsh.")
    parser.add_argument("--blend")
    parser.add_argument("--out", required=True)
    parser.add_argument("--frames", type=frame_range)
    parser.add_argument("--resolution", type=size)
    parser.add_argument("--spheres", type=int, default=Options.spheres)
    parser.add_argument("--fit-error", type=float, default=Options.fit_error)
    parser.add_argument("--heightfield")
    parser.add_argument("--heightmap-size", type=int, default=Options.heightmap_size)
    parser.add_argument("--supersample", type=int, default=Options.supersample)
    parser.add_argument("--no-colour-passes", dest="colour_passes", action="store_false",
                        help="leave out the Diffuse Color and Glossy Color passes: logsh shades the material table's "
                             "colours (the materials of render_cycles.py's direct-light truth)")
    parser.add_argument("--approximate", action="store_true",
                        help="export materials logsh cannot represent with a warning each, where the export stops")
    parser.add_argument("--sun-shadow-resolution", type=int, default=Options.sun_shadow_resolution,
                        help="texels along the longer side of each sun's shadow map, 64 to 8192; 0 writes none")
    args = parser.parse_args(argv)

    if args.blend:
        if not os.path.isfile(args.blend):
            sys.exit(f"error: {args.blend}: no such .blend file")
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend), load_ui=False)
    elif not bpy.data.filepath:
        sys.exit("error: no .blend given; pass --blend FILE (or open one: blender -b FILE -P export_scene.py -- ...)")
    scene = bpy.context.scene
    if args.spheres < 1 or not 0.0 < args.fit_error < 1.0 or args.heightmap_size < 2:
        sys.exit("error: --spheres must be >= 1, --fit-error in (0, 1), --heightmap-size >= 2")
    options = Options(out=args.out, frames=args.frames, resolution=args.resolution, spheres=args.spheres,
                      fit_error=args.fit_error, heightfield=args.heightfield,
                      heightmap_size=args.heightmap_size, supersample=args.supersample,
                      colour_passes=args.colour_passes, approximate=args.approximate,
                      sun_shadow_resolution=args.sun_shadow_resolution)
    try:
        export(scene, options)
    except ExportError as e:
        sys.exit(f"error: {e}")


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
