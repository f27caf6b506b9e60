"""Renders the analytic sphere-over-plane scene in Blender and writes it as a format-v1 scene.

A plane (material index 1) under a sphere of radius 1 at height 2 (material index 2, also
the one blocker), seen from (0, -8, 10), constant white light: on plane pixels the answer
is 1 - sin^2(alpha) cos(beta). The G-buffer is Cycles' Position, Normal, UV and Material
Index passes in a Blender 5 multilayer EXR, with the pixel filter off so that data passes
are not blended at edges.

    python -m pip install bpy          # Blender 5 as a Python module
    python blender_scripts/sphere_over_plane.py OUT_DIR [WIDTH HEIGHT]
    cargo run --release -- shade OUT_DIR

(or `blender -b -P blender_scripts/sphere_over_plane.py -- OUT_DIR`).
"""
import json
import os
import sys

import bpy
import mathutils

args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
if not args:
    sys.exit(__doc__)
out = os.path.abspath(args[0])
width, height = (int(args[1]), int(args[2])) if len(args) >= 3 else (64, 36)
os.makedirs(out, exist_ok=True)
if os.path.exists(os.path.join(out, "scene.json")):
    sys.exit(f"{out} already holds a scene; choose another directory")

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.samples = 1
scene.cycles.device = "CPU"
scene.render.resolution_x, scene.render.resolution_y = width, height
scene.render.resolution_percentage = 100
scene.render.filter_size = 0.0

def add_material(obj, name, index):
    material = bpy.data.materials.new(name)
    material.pass_index = index
    obj.data.materials.append(material)

bpy.ops.mesh.primitive_plane_add(size=40, location=(0, 0, 0))
add_material(bpy.context.object, "ground", 1)
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0, 0, 2), segments=64, ring_count=32)
bpy.ops.object.shade_smooth()
add_material(bpy.context.object, "ball", 2)

camera_data = bpy.data.cameras.new("camera")
camera = bpy.data.objects.new("camera", camera_data)
scene.collection.objects.link(camera)
scene.camera = camera
camera.location = (0, -8, 10)
camera.rotation_euler = mathutils.Vector((0, 8, -10)).to_track_quat("-Z", "Y").to_euler()

layer = scene.view_layers[0]
layer.use_pass_position = True
layer.use_pass_normal = True
layer.use_pass_uv = True
layer.use_pass_material_index = True
settings = scene.render.image_settings
settings.media_type = "MULTI_LAYER_IMAGE"  # Blender 5; older versions only need file_format
settings.file_format = "OPEN_EXR_MULTILAYER"
settings.color_depth = "32"
scene.render.filepath = os.path.join(out, "gbuffer.0001.exr")
scene.frame_set(1)
bpy.ops.render.render(write_still=True)
bpy.context.view_layer.update()

def write(name, value):
    with open(os.path.join(out, name), "w") as f:
        json.dump(value, f, indent=1)

write("camera.0001.json", {
    "frame": 1,
    "position": list(camera.matrix_world.translation),
    "matrix_world": [list(row) for row in camera.matrix_world],
    "lens_mm": camera_data.lens,
    "sensor_width_mm": camera_data.sensor_width,
    "resolution": [width, height],
})
write("blockers.0001.json", {"frame": 1, "spheres": [{"center": [0, 0, 2], "radius": 1.0}]})
write("scene.json", {
    "version": 1,
    "frames": {"start": 1, "end": 1},
    "gbuffer": "gbuffer.####.exr",
    "camera": "camera.####.json",
    "blockers": "blockers.####.json",
    "materials": {"1": {"type": "diffuse", "albedo": [1, 1, 1]}, "2": {"type": "diffuse", "albedo": [1, 1, 1]}},
    "light": {"constant": [1, 1, 1]},
})
print(f"wrote {out}")
