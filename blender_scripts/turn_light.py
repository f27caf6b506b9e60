"""Writes a copy of a .blend with its light turned about Z as `logsh render
--light-rotation DEG` turns it: the World's Environment Texture behind a Mapping node
(Point, rotation -DEG about Z, so that the sky turns by +DEG) and every Sun lamp turned
by DEG. Rendered by `render_cycles.py`, it is the converged truth of a turned render or
relight (`examples/relight_accuracy.rs` reads it as `cycles-turned-DEG.NNNN.exr`).

    python blender_scripts/turn_light.py --blend scene.blend --degrees 75 --save turned.blend

Exits with one `error:` line where the World has no Environment Texture, or where one
already has something plugged into its Vector input (a Mapping of its own).
"""
import argparse
import math
import os
import sys

import bpy
from mathutils import Matrix

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--blend", required=True, help="the .blend to read")
parser.add_argument("--degrees", required=True, type=float, help="the turn about Z, as --light-rotation")
parser.add_argument("--save", required=True, help="the .blend to write (must not exist)")
args = parser.parse_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
if os.path.exists(args.save):
    sys.exit(f"error: {args.save} exists; this script never writes over a file")
bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
world = bpy.context.scene.world
textures = [n for n in world.node_tree.nodes if n.type == "TEX_ENVIRONMENT"] if world and world.use_nodes else []
if len(textures) != 1:
    sys.exit(f"error: {args.blend}: the World has {len(textures)} Environment Textures; one is turned")
texture = textures[0]
if texture.inputs["Vector"].is_linked:
    sys.exit(f"error: {args.blend}: the Environment Texture's Vector input is already linked")
nodes, links = world.node_tree.nodes, world.node_tree.links
coordinates = nodes.new("ShaderNodeTexCoord")
mapping = nodes.new("ShaderNodeMapping")
mapping.vector_type = "POINT"
mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(-args.degrees))
links.new(coordinates.outputs["Generated"], mapping.inputs["Vector"])
links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
turn = Matrix.Rotation(math.radians(args.degrees), 4, "Z")
for lamp in bpy.data.objects:
    if lamp.type == "LIGHT" and lamp.data.type == "SUN":
        lamp.matrix_world = turn @ lamp.matrix_world
bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.save), check_existing=False)
print(f"wrote {args.save}")
