"""The geometry of an export: the objects' triangles, the ground plane, the blocker
spheres fitted per object (`blockers.py`), the frame of each sun's shadow map around them,
the height map sampled from the terrain, the camera per frame and the reflection G-buffer
of water."""

import bpy
import mathutils
import numpy as np
from mathutils.bvhtree import BVHTree

from . import blockers as blocker_fit
from .exr import write_exr
from .common import ExportError, FLAT_THICKNESS, GEOMETRY_TYPES, new_file


# ---- the scene as Cycles renders it -----------------------------------------------------

class EvaluateAsRendered(bpy.types.RenderEngine):
    """A render engine that draws nothing: rendering with it is how the exporter is handed
    the scene evaluated as a render evaluates it (Blender's render depsgraph: modifiers
    with their render visibility and levels, a Subdivision Surface at its Render level,
    particles and Geometry Nodes as rendered, the render's view layer), which a script's
    `evaluated_depsgraph_get`, the viewport's, is not. The G-buffer is Cycles', so the
    blockers, the height map and the reflection rays must see what it sees."""
    bl_idname = "LOGSH_EXPORT_EVALUATION"
    bl_label = "logsh export (evaluation only)"
    job = None

    def render(self, depsgraph):
        job = EvaluateAsRendered.job
        try:
            job["result"] = job["work"](depsgraph)
        except BaseException as error:  # Blender would print it and carry on
            job["error"] = error


def as_rendered(scene, view_layer, work, changes):
    """`work(depsgraph)` on the scene's current frame evaluated as Cycles renders it
    (`EvaluateAsRendered`), and its result. The engine is registered on the first call and
    unregistered by `changes`."""
    if not EvaluateAsRendered.is_registered:
        bpy.utils.register_class(EvaluateAsRendered)
        changes.on_undo(lambda: bpy.utils.unregister_class(EvaluateAsRendered))
    job = {"work": work}
    EvaluateAsRendered.job = job
    engine = scene.render.engine
    scene.render.engine = EvaluateAsRendered.bl_idname
    try:
        bpy.ops.render.render(write_still=False, scene=scene.name, layer=view_layer.name)
    finally:
        scene.render.engine = engine
        EvaluateAsRendered.job = None
    if "error" in job:
        raise job["error"]
    if "result" not in job:
        raise ExportError(f"Blender did not evaluate frame {scene.frame_current} of scene \"{scene.name}\" for "
                          "rendering")
    return job["result"]


# ---- geometry --------------------------------------------------------------------------

def world_triangles(obj_eval, matrix):
    """(T, 3, 3) world-space triangles of an evaluated object, or None without geometry,
    wound as the mesh is seen from outside: a transform that mirrors (a negative scale on
    one or three axes) turns the winding over, and the blocker fit's inside test reads
    the side of a face from it, so such a transform's triangles are wound back."""
    mesh = obj_eval.to_mesh()
    try:
        if mesh is None or len(mesh.polygons) == 0:
            return None
        mesh.calc_loop_triangles()
        co = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
        tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
        mesh.loop_triangles.foreach_get("vertices", tris)
    finally:
        obj_eval.to_mesh_clear()
    m = np.array(matrix)
    world = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    corners = tris.reshape(-1, 3)
    if np.linalg.det(m[:3, :3]) < 0.0:
        corners = corners[:, ::-1]
    return world[corners]


def evaluated_triangles(obj, depsgraph):
    """`world_triangles` of `obj` as `depsgraph` evaluates it, where it stands then."""
    evaluated = obj.evaluated_get(depsgraph)
    return world_triangles(evaluated, evaluated.matrix_world)


def triangle_tree(triangles):
    """Blender's BVH over (T, 3, 3) triangles, for nearest-point and ray queries."""
    vertices = triangles.reshape(-1, 3)
    return BVHTree.FromPolygons([tuple(v) for v in vertices], [(3 * i, 3 * i + 1, 3 * i + 2) for i in range(len(triangles))])


def is_flat(triangles):
    points = triangles.reshape(-1, 3)
    centred = points - points.mean(axis=0)
    extents = np.sort(np.ptp(centred @ np.linalg.svd(centred, full_matrices=False)[2].T, axis=0))
    return extents[-1] <= 0 or extents[0] < FLAT_THICKNESS * extents[-1]


def find_ground(objects, terrain, depsgraph, log):
    """The height of the scene's floor and its object's name, or None, when there is no
    height field: the lowest flat,
    horizontal mesh whose extent covers every other object's in x and y (an object may set
    the custom property `logsh_ground` to false to be left out). logsh then treats it as
    an infinite plane hiding the lower hemisphere from everything above it, as Cycles'
    floor hides it; without this a constant or bright-bottomed World would light the
    undersides of objects from below the floor."""
    if terrain is not None:
        return None
    bounds = {}
    for obj in objects:
        if obj.type not in GEOMETRY_TYPES or obj.is_instancer:
            continue
        triangles = evaluated_triangles(obj, depsgraph)
        if triangles is not None:
            points = triangles.reshape(-1, 3)
            bounds[obj.name] = (points.min(axis=0), points.max(axis=0), obj)
    best = None
    for name, (lo, hi, obj) in bounds.items():
        if not obj.get("logsh_ground", True):
            continue
        size = max(hi[0] - lo[0], hi[1] - lo[1])
        if size <= 0 or hi[2] - lo[2] > 1e-4 * size:
            continue
        others = [b for other, b in bounds.items() if other != name]
        if not others:
            continue
        z = 0.5 * (lo[2] + hi[2])
        covers = all(o_lo[0] >= lo[0] and o_lo[1] >= lo[1] and o_hi[0] <= hi[0] and o_hi[1] <= hi[1]
                     for o_lo, o_hi, _ in others)
        above = all(o_lo[2] >= z - 1e-3 * size for o_lo, _, _ in others)
        if covers and above and (best is None or z < best[0]):
            best = (z, name)
    if best is not None:
        log(f"ground: \"{best[1]}\" at z = {best[0]:.4g} hides the lower hemisphere from the objects above it "
            "(set its logsh_ground property to false to leave it out)")
        return best
    return None


def object_indices(objects, changes):
    """Gives every renderable object its own pass index 1..N (undone after the export), so
    that the G-buffer's Object Index pass and the blocker spheres name the same object: a
    receiver takes no shadow from its own spheres that hold it (docs/design.md)."""
    index_of = {}
    for i, obj in enumerate(sorted(objects, key=lambda o: o.name), start=1):
        changes.set(obj, "pass_index", i)
        index_of[obj.name] = i
    return index_of


def is_closed(triangles):
    """Whether every edge of the triangles is shared by two of them (vertices at the same
    place, to a millionth of the mesh's extent, counted as one, so that a mesh split at
    its UV seams is still closed)."""
    points = triangles.reshape(-1, 3)
    extent = float(np.ptp(points, axis=0).max()) or 1.0
    _, ids = np.unique(np.round(points / (1e-6 * extent)).astype(np.int64), axis=0, return_inverse=True)
    ids = ids.reshape(-1, 3)
    edges = np.sort(np.concatenate([ids[:, [0, 1]], ids[:, [1, 2]], ids[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool((counts >= 2).all())


# Directions of the parity test's rays: off the axes, so that they do not run along the
# faces of axis-aligned meshes.
PARITY_RAYS = [mathutils.Vector(d).normalized() for d in ((1.0, 0.0123, 0.0271), (0.0187, 1.0, -0.0311),
                                                           (-0.0217, 0.0143, 1.0))]


def crossings(tree, origin, direction, step):
    """How many faces of `tree` the ray from `origin` along `direction` crosses."""
    count = 0
    while True:
        location, _, _, _ = tree.ray_cast(origin, direction)
        if location is None:
            return count
        count += 1
        origin = location + direction * step


def is_sheet(triangles, count=2000, seed=0):
    """Whether the mesh is an open sheet (a bent plane, cloth) rather than a solid: open
    (`is_closed`), and of the points of its grown bounding box that lie on the inner side
    of their nearest face (`volume_sample`'s inside), fewer than half are inside by ray
    parity (an odd number of crossings both ways along each of three lines). Behind a
    sheet the nearest face's side fills a slab out to the box, which a fit would cover
    with spheres reaching the ground (a waving plane's shadow came out 0.059 too dark);
    a model with a few holes (Suzanne's eyes) keeps nearly all of its inside."""
    if is_closed(triangles):
        return False
    points, inside, _, _ = volume_sample(triangles, count, seed)
    candidates = np.flatnonzero(inside)
    if candidates.size == 0:
        return True
    tree = triangle_tree(triangles)
    step = 1e-6 * (float(np.ptp(triangles.reshape(-1, 3), axis=0).max()) or 1.0)

    def enclosed(point):
        # Along how many of the three lines through the point both half-rays cross an odd
        # number of faces, as they do from inside a solid.
        return sum(crossings(tree, point, d, step) % 2 == 1 and crossings(tree, point, -d, step) % 2 == 1
                   for d in PARITY_RAYS)

    inside_by_parity = sum(enclosed(mathutils.Vector(points[i])) == len(PARITY_RAYS) for i in candidates)
    return inside_by_parity < 0.5 * candidates.size


def volume_sample(triangles, count=16000, seed=0):
    """Uniform points over the mesh's grown bounding box, whether each lies inside the mesh
    (the side of the nearest surface point's face it lies on) and its distance to the
    surface; and the volume each point stands for."""
    points, box_volume = blocker_fit.sample_box(triangles, count, seed)
    tree = triangle_tree(triangles)
    inside = np.zeros(count, dtype=bool)
    depth = np.zeros(count)
    for i, p in enumerate(points):
        location, normal, _, distance = tree.find_nearest(mathutils.Vector(p))
        if location is not None:
            inside[i] = (mathutils.Vector(p) - location).dot(normal) < 0.0
            depth[i] = distance
    return points, inside, depth, box_volume / count


def export_blockers(scene, depsgraph, objects, terrain, index_of, table, object_index, options, fits, frame, log,
                    ground=None):
    """Spheres of every blocker object at this frame, and the objects that cast sun
    shadows as `(object, instancer, vertices)`: the original object, the original object
    whose instance it is (None when it is not one) and the vertices of its world-space
    triangles at this frame. The sun shadow maps hold exactly these objects (`exporter.py`,
    `render_depths`): the blockers, and the flat meshes and open sheets that no sphere
    fits but for the ground plane (the object named `ground`). Prints each fit's error."""
    allowed = {o.name for o in objects}
    spheres, reports, casters = [], [], []
    for instance in depsgraph.object_instances:
        original = instance.object.original
        if original.name not in allowed or original == terrain or original.type not in GEOMETRY_TYPES:
            continue
        count = original.get("logsh_spheres")
        if count is not None and int(count) <= 0:
            continue
        instancer = instance.parent.original.name if instance.is_instance and instance.parent else ""
        key = (original.name, instancer, tuple(instance.persistent_id) if instance.is_instance else ())
        matrix = np.array(instance.matrix_world)
        triangles = world_triangles(instance.object, instance.matrix_world)
        if triangles is None:
            continue
        fit = fits.get(key)
        parent = instance.parent.original if instance.is_instance and instance.parent else None
        if fit == "skip":
            continue
        if fit == "casts":
            casters.append((original, parent, triangles.reshape(-1, 3)))
            continue
        if abs(np.linalg.det(matrix[:3, :3])) <= 1e-12 * np.abs(matrix[:3, :3]).max() ** 3:
            # Scaled to nothing along an axis (keyed to 0, say): it renders nothing.
            continue
        inverse = np.linalg.inv(matrix)
        local = triangles.reshape(-1, 3) @ inverse[:3, :3].T + inverse[:3, 3]
        if fit is None or not fit.follows(local):
            if count is None and fit is None:
                materials = {s.material.name for s in original.material_slots if s.material}
                if materials and all(table[index_of[m]]["type"] == "water" for m in materials):
                    fits[key] = "skip"
                    log(f"note: \"{original.name}\" is water only; not a blocker")
                    continue
                flat = is_flat(triangles)
                if flat or is_sheet(triangles):
                    what = "flat" if flat else "an open sheet, not a solid"
                    casts = original.name != ground
                    fits[key] = "casts" if casts else "skip"
                    log(f"note: \"{original.name}\" is {what}; not a blocker"
                        + (", so it casts sun shadows only (a Solidify modifier makes it a solid" if casts else
                           " (the ground") + "; or set its logsh_spheres property to force spheres)")
                    if casts:
                        casters.append((original, parent, triangles.reshape(-1, 3)))
                    continue
            name = original.name + (f" (instanced by {instancer}, {instance.persistent_id[0]})" if instance.is_instance else "")
            points, inside, depth, point_volume = volume_sample(triangles)
            try:
                volume = blocker_fit.VolumeFit(name, points, inside, depth, point_volume,
                                               count=int(count) if count is not None else None,
                                               error_target=options.fit_error, max_count=options.spheres,
                                               moments=blocker_fit.mesh_moments(triangles))
            except ValueError as e:
                raise ExportError(str(e)) from None
            fit = blocker_fit.ObjectSpheres(name, volume, matrix, local)
            fits[key] = fit
            reports.append((name, fit.count, fit.error))
        centres, radii = fit.spheres(matrix)
        object_id = object_index.get(original.name, 0)
        spheres += [{"center": [float(v) for v in c], "radius": float(r), "object": object_id}
                    for c, r in zip(centres, radii)]
        casters.append((original, parent, triangles.reshape(-1, 3)))
    report_fit_errors(reports, frame, log)
    return spheres, casters


# Texels of the sun shadow map beyond the blockers' outline on every side.
SUN_SHADOW_MARGIN = 2
# The least texels along the shorter side of a sun shadow map.
SUN_SHADOW_MIN_SIDE = 16


def sun_shadow_frame(axis, points, resolution):
    """Where the shadow map of the sun towards `axis` (unit) lies, for blockers of
    world-space vertices `points` (N, 3): an orthographic view along -axis whose image
    plane, centred on `origin`, lies beyond every vertex towards the sun and covers their
    outline with a margin of `SUN_SHADOW_MARGIN` square texels on each side, `resolution`
    of them along the longer side (`sun_shadows` of blockers.####.json, `exporter.py`).

    `right` is horizontal and `up` climbs (world +Z projected onto the plane); with the
    sun straight overhead, where that has no direction, they are world +X and +Y. Returns
    a dict of `right`, `up`, `origin`, `size` ([w, h] metres), `texels` ([nx, ny]),
    `texel` (metres), `gap` (from the plane to the nearest vertex) and `depth` (from the
    plane to the farthest); None when the vertices project onto a single point."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    reference = np.array([0.0, 0.0, 1.0])
    if np.linalg.norm(np.cross(reference, axis)) < 1e-3:
        reference = np.array([0.0, 1.0, 0.0])
    right = np.cross(reference, axis)
    right /= np.linalg.norm(right)
    up = np.cross(axis, right)
    u, v, s = points @ right, points @ up, points @ axis
    extents = np.array([np.ptp(u), np.ptp(v)])
    longest = int(np.argmax(extents))
    if not extents[longest] > 0.0:
        return None
    texel = float(extents[longest]) / (resolution - 2 * SUN_SHADOW_MARGIN)
    span = extents[1 - longest] + 2 * SUN_SHADOW_MARGIN * texel
    texels = [resolution, resolution]
    texels[1 - longest] = min(resolution, max(SUN_SHADOW_MIN_SIDE, int(np.ceil(span / texel - 1e-9))))
    # Beyond the nearest vertex by a few texels and a little of the blockers' size: the
    # render's clipping plane fits between.
    gap = max(4.0 * texel, 1e-3 * float(extents[longest]))
    top = float(s.max()) + gap
    return {
        "right": right,
        "up": up,
        "origin": right * 0.5 * (u.min() + u.max()) + up * 0.5 * (v.min() + v.max()) + axis * top,
        "size": [texels[0] * texel, texels[1] * texel],
        "texels": texels,
        "texel": texel,
        "gap": gap,
        "depth": top - float(s.min()),
    }


def report_fit_errors(reports, frame, log):
    """Each new fit's sphere count and its error: the volume of the symmetric difference
    between the spheres' union and the mesh, relative to the mesh's volume."""
    if not reports:
        return
    if len(reports) <= 12:
        for name, count, error in reports:
            log(f"frame {frame}: {name}: {count} sphere(s), volume error {100 * error:.1f}%")
    else:
        errors = np.array([e for _, _, e in reports])
        worst = reports[int(np.argmax(errors))][0]
        log(f"frame {frame}: {len(reports)} objects fitted with {sum(c for _, c, _ in reports)} spheres; volume error "
            f"{100 * errors.mean():.1f}% on average, {100 * errors.max():.1f}% at worst ({worst})")


def export_heightmap(terrain, depsgraph, out, options, log, name="heightmap.exr"):
    """Samples the terrain's top surface on a corner-registered grid over its XY bounds,
    into the file `name`."""
    triangles = evaluated_triangles(terrain, depsgraph)
    if triangles is None:
        raise ExportError(f"height field \"{terrain.name}\" has no faces")
    vertices = triangles.reshape(-1, 3)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    if not (hi[0] > lo[0] and hi[1] > lo[1]):
        raise ExportError(f"height field \"{terrain.name}\" has no extent in x or y")
    long_side = max(hi[0] - lo[0], hi[1] - lo[1])
    columns = max(2, int(round(options.heightmap_size * (hi[0] - lo[0]) / long_side)))
    rows = max(2, int(round(options.heightmap_size * (hi[1] - lo[1]) / long_side)))
    tree = triangle_tree(triangles)
    top = hi[2] + 1.0 + 0.01 * long_side
    heights = np.full((rows, columns), np.nan, dtype=np.float32)
    down = mathutils.Vector((0.0, 0.0, -1.0))
    for j in range(rows):
        y = lo[1] + (hi[1] - lo[1]) * j / (rows - 1)
        for i in range(columns):
            x = lo[0] + (hi[0] - lo[0]) * i / (columns - 1)
            hit = tree.ray_cast(mathutils.Vector((x, y, top)), down)[0]
            if hit is None:  # the outermost samples lie on the edges; nudge inwards
                nx = min(max(x, lo[0] + 1e-5 * long_side), hi[0] - 1e-5 * long_side)
                ny = min(max(y, lo[1] + 1e-5 * long_side), hi[1] - 1e-5 * long_side)
                hit = tree.ray_cast(mathutils.Vector((nx, ny, top)), down)[0]
            if hit is not None:
                heights[j, i] = hit.z
    holes = np.isnan(heights)
    if holes.all():
        raise ExportError(f"height field \"{terrain.name}\": no vertical ray hits it")
    if holes.any():
        log(f"note: height field \"{terrain.name}\": {int(holes.sum())} of {holes.size} samples fall in holes; set to its lowest point")
        heights[holes] = np.nanmin(heights)
    # Row 0 of the map lies at min y and is the file's first scan line.
    write_exr(new_file(out, name), {"Y": heights})
    log(f"height map {name}: {columns}x{rows} samples of \"{terrain.name}\" over x {lo[0]:.3g}..{hi[0]:.3g}, "
        f"y {lo[1]:.3g}..{hi[1]:.3g}")
    return {"heights": name, "min": [float(lo[0]), float(lo[1])], "max": [float(hi[0]), float(hi[1])]}


def terrain_moves(scene, view_layer, terrain, frames, changes):
    """Whether the terrain's evaluated surface differs between `frames`: anything that
    moves it (an animated transform, modifiers such as Wave or Ocean, shape keys,
    armatures, geometry nodes) shows in its world-space triangles. Compared to 1e-6 of its
    extent, far below a height map's spacing."""
    first = None
    for frame in frames:
        scene.frame_set(frame)
        triangles = as_rendered(scene, view_layer, lambda depsgraph: evaluated_triangles(terrain, depsgraph), changes)
        if triangles is None:
            raise ExportError(f"height field \"{terrain.name}\" has no faces on frame {frame}")
        if first is None:
            first = triangles
            scale = float(np.ptp(triangles.reshape(-1, 3), axis=0).max()) or 1.0
        elif triangles.shape != first.shape or np.abs(triangles - first).max() > 1e-6 * scale:
            return True
    return False


# ---- camera and reflection -------------------------------------------------------------

def camera_json(scene, frame, width, height):
    obj = scene.camera
    data = obj.data
    if data.type != "PERSP":
        kind = {"ORTHO": "Orthographic", "PANO": "Panoramic"}.get(data.type, data.type)
        raise ExportError(f"camera \"{obj.name}\" is {kind}; logsh reads perspective cameras only: set its "
                          "Lens > Type to Perspective")
    if data.shift_x != 0.0 or data.shift_y != 0.0:
        raise ExportError(f"camera \"{obj.name}\" has a lens shift ({data.shift_x:g}, {data.shift_y:g}); logsh's "
                          "camera has none: set its Lens > Shift X and Y to 0")
    # logsh reads Blender's default sensor fit (AUTO: the sensor width spans the longer
    # image side); other fits are written as the AUTO width that gives the same view.
    landscape = width >= height
    if data.sensor_fit == "HORIZONTAL":
        sensor = data.sensor_width if landscape else data.sensor_width * height / width
    elif data.sensor_fit == "VERTICAL":
        sensor = data.sensor_height * width / height if landscape else data.sensor_height
    else:
        sensor = data.sensor_width
    m = obj.matrix_world
    return {
        "frame": frame,
        "position": list(m.translation),
        "matrix_world": [list(row) for row in m],
        "lens_mm": data.lens,
        "sensor_width_mm": sensor,
        "resolution": [width, height],
    }


def pixel_rays(camera):
    """Unit world directions through every pixel centre, rows from the top (as logsh's
    `Camera::ray_direction`)."""
    w, h = camera["resolution"]
    half = 0.5 * camera["sensor_width_mm"] / camera["lens_mm"]
    hw, hh = (half, half * h / w) if w >= h else (half * w / h, half)
    x = (2.0 * (np.arange(w) + 0.5) / w - 1.0) * hw
    y = (1.0 - 2.0 * (np.arange(h) + 0.5) / h) * hh
    local = np.stack(np.broadcast_arrays(x[None, :], y[:, None], -np.ones((h, w))), axis=-1)
    world = local @ np.array(camera["matrix_world"])[:3, :3].T
    return world / np.linalg.norm(world, axis=-1, keepdims=True)


class SurfaceLookup:
    """Smooth (interpolated) normals and materials at ray hits, per evaluated object.

    `Scene.ray_cast` returns the face normal; Cycles' Normal pass is the interpolated
    shading normal, so the reflection G-buffer interpolates corner normals the same way.
    """

    def __init__(self, depsgraph):
        self.depsgraph = depsgraph
        self.cache = {}

    def _mesh(self, obj):
        entry = self.cache.get(obj.name)
        if entry is None:
            evaluated = obj.evaluated_get(self.depsgraph)
            mesh = evaluated.to_mesh()
            mesh.calc_loop_triangles()
            n = len(mesh.loop_triangles)
            verts = np.empty(n * 3, dtype=np.int64)
            loops = np.empty(n * 3, dtype=np.int64)
            polys = np.empty(n, dtype=np.int64)
            mesh.loop_triangles.foreach_get("vertices", verts)
            mesh.loop_triangles.foreach_get("loops", loops)
            mesh.loop_triangles.foreach_get("polygon_index", polys)
            co = np.empty(len(mesh.vertices) * 3)
            mesh.vertices.foreach_get("co", co)
            normals = np.empty(len(mesh.loops) * 3)
            mesh.corner_normals.foreach_get("vector", normals)
            material_index = np.empty(len(mesh.polygons), dtype=np.int64)
            mesh.polygons.foreach_get("material_index", material_index)
            slots = [s.material.name if s.material else None for s in evaluated.material_slots]
            evaluated.to_mesh_clear()
            order = np.argsort(polys, kind="stable")
            entry = {
                "tri_vertices": verts.reshape(-1, 3), "tri_loops": loops.reshape(-1, 3), "tri_poly": polys,
                "co": co.reshape(-1, 3), "normals": normals.reshape(-1, 3), "material_index": material_index,
                "slots": slots, "order": order, "sorted_poly": polys[order],
            }
            self.cache[obj.name] = entry
        return entry

    def at(self, obj, face, location, matrix, ray):
        """(shading normal facing the ray, material name) of a hit."""
        m = self._mesh(obj)
        inverse = matrix.inverted()
        local = np.array(inverse @ location)
        lo, hi = np.searchsorted(m["sorted_poly"], [face, face + 1])
        best, best_weights = None, None
        for t in m["order"][lo:hi]:
            a, b, c = m["co"][m["tri_vertices"][t]]
            weights = _barycentric(local, a, b, c)
            if best is None or weights.min() > best_weights.min():
                best, best_weights = t, weights
        if best is None:
            normal = mathutils.Vector((0.0, 0.0, 1.0))
        else:
            n_local = best_weights @ m["normals"][m["tri_loops"][best]]
            normal = (inverse.transposed().to_3x3() @ mathutils.Vector(n_local)).normalized()
        if normal.dot(ray) > 0.0:  # Cycles turns the normal towards the viewer on back faces
            normal = -normal
        slot = m["material_index"][face] if face < len(m["material_index"]) else 0
        name = m["slots"][slot] if slot < len(m["slots"]) else None
        return normal, name


def _barycentric(p, a, b, c):
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
    d20, d21 = v2 @ v0, v2 @ v1
    denominator = d00 * d11 - d01 * d01
    if denominator == 0.0:
        return np.array([1.0, 0.0, 0.0])
    v = (d11 * d20 - d01 * d21) / denominator
    w = (d00 * d21 - d01 * d20) / denominator
    return np.array([1.0 - v - w, v, w])


def write_reflection(scene, depsgraph, camera, index_of, water, path):
    """The reflection G-buffer: what each water pixel's mirror ray hits."""
    w, h = camera["resolution"]
    rays = pixel_rays(camera)
    origin = mathutils.Vector(camera["position"])
    lookup = SurfaceLookup(depsgraph)
    position = np.zeros((h, w, 3), dtype=np.float32)
    normal = np.zeros((h, w, 3), dtype=np.float32)
    index = np.zeros((h, w), dtype=np.float32)
    objects = np.zeros((h, w), dtype=np.float32)
    scale = max(1.0, origin.length)
    for y in range(h):
        for x in range(w):
            d = mathutils.Vector(rays[y, x])
            hit, location, _, face, obj, matrix = scene.ray_cast(depsgraph, origin, d)
            if not hit:
                continue
            n, material = lookup.at(obj, face, location, matrix, d)
            if index_of.get(material) not in water:
                continue
            mirror = d - 2.0 * d.dot(n) * n
            start = location + n * (1e-5 * scale)
            hit, location, _, face, obj, matrix = scene.ray_cast(depsgraph, start, mirror)
            if not hit:
                continue  # the sky: material 0
            n, material = lookup.at(obj, face, location, matrix, mirror)
            position[y, x], normal[y, x] = location, n
            index[y, x] = index_of.get(material, 0)
            objects[y, x] = obj.original.pass_index
    channels = {"ViewLayer.IndexMA.X": index, "ViewLayer.IndexOB.X": objects}
    for k, axis in enumerate("XYZ"):
        channels[f"ViewLayer.Position.{axis}"] = position[..., k]
        channels[f"ViewLayer.Normal.{axis}"] = normal[..., k]
    write_exr(path, channels)
