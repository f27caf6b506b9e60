"""Fits blocker spheres to Blender's primitive meshes with the exporter's own code and
prints, per primitive, the sphere count, the fit's volume error and the spheres, as one
JSON object (read by `tests/blender.rs::primitives_fit_their_volume`). The `_mirrored`
ones are the same meshes under a negative scale they are symmetric under, which turns
their triangles' winding over."""
import json
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "blender_scripts"))
from logsh_exporter import blockers, geometry  # noqa: E402

bpy.ops.wm.read_factory_settings(use_empty=True)
add = {
    "uv_sphere": lambda: bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=32, ring_count=16),
    "cube": lambda: bpy.ops.mesh.primitive_cube_add(size=2.0),
    "cone": lambda: bpy.ops.mesh.primitive_cone_add(radius1=1.0, depth=2.0),
    "torus": lambda: bpy.ops.mesh.primitive_torus_add(major_radius=1.0, minor_radius=0.25),
}
result = {}
scales = {name: (1.0, 1.0, 1.0) for name in add}
scales.update({"cube_mirrored": (-1.0, 1.0, 1.0), "cone_mirrored": (-1.0, 1.0, 1.0),
               "torus_mirrored": (-1.0, -1.0, -1.0)})
for name, scale in scales.items():
    add[name.removesuffix("_mirrored")]()
    obj = bpy.context.active_object
    obj.scale = scale
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    triangles = geometry.world_triangles(obj.evaluated_get(depsgraph), obj.matrix_world)
    points, inside, depth, point_volume = geometry.volume_sample(triangles)
    fit = blockers.VolumeFit(name, points, inside, depth, point_volume, moments=blockers.mesh_moments(triangles))
    result[name] = {"count": len(fit.radii), "error": fit.error,
                    "centres": fit.centres.tolist(), "radii": fit.radii.tolist(),
                    "mesh_volume": blockers.mesh_moments(triangles)[0]}
    bpy.data.objects.remove(obj)
print(json.dumps(result))
