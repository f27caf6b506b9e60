"""Exports the open Blender scene as a logsh scene (format v1, `docs/design.md`).

Used by the command line (`blender_scripts/export_scene.py`) and by the add-on's
operator (`__init__.py`); both call `export(scene, Options(...))`.

Everything is taken from the scene as Cycles renders it, the render's view layer
evaluated with render settings (`geometry.as_rendered`): a modifier shown in renders only,
a Subdivision Surface at its Render level, particles and Geometry Nodes as rendered. A
Render Region is left out: the whole frame is exported. Geometry that Geometry Nodes or
particles make without a material (which Cycles renders with its default surface, and
which would have no material index), and hair (particle hair, Curves objects), whose
strands no sphere fits, stop the export with the object's name (`Options.approximate`:
a warning each).

What is written into the output directory, per frame `####`:

- `gbuffer.####.exr`: Cycles' Position, Normal, UV and Material Index passes in Blender's
  own multilayer EXR (32-bit float, ZIP). Data passes must not be blended at object
  edges (a pixel half ball, half floor would get a position between them and a material
  index of 1.5), so each pixel gets exactly one sample at its centre: 1 sample, a
  Gaussian pixel filter of the smallest width Cycles accepts (0.01 px), no denoising, no motion
  blur, no depth of field. With `colour_passes` (the default), the file also holds
  Cycles' Diffuse Color and Glossy Color passes: the material as Blender evaluates it at
  each pixel (textures, vertex colours, every node in front of the BSDF, and the
  Principled BSDF's layers weighed as Cycles weighs them, the specular layer with its
  Fresnel term at the pixel's view angle), which logsh multiplies the light through the
  diffuse and the glossy lobe by (scene.json `colour_passes`). The file also holds
  Blender's Combined pass, which nothing reads. With `supersample` N > 1 (`--supersample`), the G-buffers and the reflection
  G-buffer are N times the output size, one sample at each sub-pixel centre, which logsh
  shades and resolves to the camera's size (scene.json `supersample`; the cameras keep the
  output size).
- `reflection.####.exr` when a material is water: for each water pixel, the world
  position, normal and material index of the surface seen in the mirror direction, found
  by ray casting the evaluated scene (`Scene.ray_cast`); Blender 4's single-part layout
  (`ViewLayer.Position.X`, ..., `ViewLayer.IndexMA.X`), written by `exr.py`.
- `camera.####.json`: the scene camera (perspective only, no lens shift).
- `blockers.####.json`: spheres for every mesh that is not the height field, evaluated at
  that frame (modifiers, armatures, shape keys, animation applied); see `blockers.py`.
  Spheres shadow the sun along their own outline, not the mesh's, so for each sun of the
  frame's `lights` (Sun lamps and a Sky Texture's sun), and for each sun that logsh
  will take out of the environment map (`environment_suns`, turned by the frame's
  Mapping rotation; none within half a degree of a lamp's, whose map serves it), the
  file's `sun_shadows` also names a shadow map, `sun_shadow.####.K.exr` (K the sun's
  place among those suns): Cycles' depth pass of exactly the objects that have spheres,
  seen through an orthographic camera from the sun's side and from beyond them
  (`render_depths`). Each entry holds `image`, `axis` (the sun's direction as `lights`
  has it, or as the map's sun lies in the world), `origin` (the centre of the image
  plane, beyond every blocker towards the sun), `right` and `up`
  (unit, right x up = axis) and `size` ([w, h] metres along them). The EXR's channel
  `Z`, row 0 along the +up edge and column 0 along the -right edge, is at texel (i, j)
  the distance along -axis from the plane to the first blocker surface on the ray
  through the texel centre `origin + right ((i + 0.5) / nx - 0.5) w + up (0.5 -
  (j + 0.5) / ny) h`, so a surface point x has Z = (origin - x) . axis, and 1e10 where
  the ray meets none; its channel `Zfar` the distance to the last blocker surface on
  that ray, where it leaves the blockers for good (at least Z; 1e10 where Z is). One
  sample at each centre, as in the G-buffer; `Options.sun_shadow_resolution` square
  texels along the longer side, the map covering the blockers' outline with a margin of
  2 texels. Without a sun or a blocker the key is left out.
- `heightmap.exr`: the height field object sampled on a grid by vertical rays; one map
  per frame, `heightmap.####.exr`, when the terrain moves within the exported frames (an
  animated transform, modifiers such as Wave or Ocean, shape keys, armatures, geometry
  nodes: `terrain_moves`).
- `frame.####.json` (scene.json `per_frame`) when something beside the G-buffers changes
  from frame to frame: a keyed lamp's `lights`, a keyed World's Strength, Mapping rotation
  or constant colour (`light`), a moving terrain's rectangle (`heightfield`). A World
  that logsh bakes (below) and that changes stops the export.
- `sky.exr` when the World uses an environment texture (a Mapping node in front of it
  becomes the light's `rotation`), or a bake of the World by Cycles when it uses anything
  else (a Sky Texture, a gradient, a linked strength; a Sky Texture's sun disc is left out
  of the bake and written as a sun of `lights`, `bake_world`); `scene.json`, whose
  `lights` holds every Sun lamp that renders (direction towards the sun, Angle, Strength, Color)
  and every Point lamp (world position, Radius, Power, Color, Soft Falloff), Exposure
  folded into Strength or Power; a keyed lamp as it is on each frame (`frame.####.json`).
  Any other lamp (Spot, Area), or a lamp setting logsh does not model (nodes, Temperature, Cast Shadow off, Diffuse or
  Specular factors other than 1, Normalize off, hidden from Diffuse or Glossy rays),
  stops the export with the lamp's name.
- `view_lut.exr` unless the Color Management is plain Standard: Blender's view transform,
  look and gamma sampled through `Image.save_render` on a 33^3 grid of linear colours, which
  logsh's previews apply after the exposure (scene.json `view`, `src/scene/view.rs`).

Scene markup, all optional (custom properties, set in the Object or Material tab):

- object `logsh_heightfield` (true): this mesh is the terrain (at most one);
- object `logsh_spheres` (int): blocker spheres for this object, 0 for none;
- object `logsh_ground` (false): this flat mesh is not the ground plane (by default the
  lowest flat horizontal mesh under every other object is, when there is no height field);
- material `logsh_type`: `diffuse`, `phong`, `water` or `heightfield`. Default: `phong`
  for a Principled BSDF with metallic >= 0.5 or roughness < 0.4, else `diffuse`; every
  material on the height field object is `heightfield` (with colour passes, a Principled
  BSDF is `phong` wherever it is: see below).
- material `logsh_tint` (colour): a water tint other than its base colour.

What a material may hold: a Principled BSDF, a Diffuse BSDF or a Glossy BSDF feeding the
Material Output, with any nodes in front of them. Faces with no material (an object
without one, or an empty slot) take a new material for the export (`logsh default`,
removed again after it), whose Principled BSDF renders as Cycles' default surface, the
same Diffuse and Glossy Color passes. The Principled BSDF's Transmission,
Subsurface, Sheen and Coat weights must be at most `NEGLIGIBLE_WEIGHT` and unlinked, and
it must not emit (Emission Strength times Emission Color). Water with colour passes is
the other way round: logsh shades it as its reflection alone (the reflection G-buffer's
point times the Glossy Color pass, the Fresnel reflectance at the pixel's view angle), so
it must transmit (Transmission Weight 1) or be a metal, and not have a diffuse layer.
Anything else (another surface node such as a Mix Shader, Glass or Emission, a linked or
heavier weight) stops the export, naming the material and the node;
`Options.approximate` (`--approximate`) makes each a warning instead, which the summary
counts. A Roughness driven by nodes is always a warning: logsh shades one lobe width per
material. With colour passes, that width is fitted to Blender's own evaluation: an AOV
Output node (`logsh_roughness`, removed again after the export) carries what drives the
socket into the first exported frame's G-buffer, and the material takes the root mean
square of its pixels' roughness; without them, the socket's own value.

With colour passes, every Principled BSDF that is not water is `phong`, on the terrain
too and whatever its `logsh_type` says (its specular layer shaded as a GGX lobe, weighed
per pixel by the Glossy Color pass, which is black where Specular IOR Level is 0), and the
table's colours are each material's mean Diffuse and Glossy Color over its pixels in the
first frame (`fit_to_passes`), which logsh uses only for the points seen in water's
reflection (the exporter ray casts the reflection G-buffer, which has no colour passes of
its own); a material out of view keeps the colours below. What the passes cannot carry,
the reflectance at normal incidence that a lamp's highlight follows through the Fresnel
term, is the entry's `fresnel` (the converted specular below, averaged over R, G and B; 1
for a Glossy BSDF; left out where a node drives it). Without them (`colour_passes`
False, `--no-colour-passes`, the materials of `render_cycles.py`'s direct-light truth),
the conversion is the whole of the material (logsh has no Fresnel term and a Phong lobe
about the mirror direction, `docs/design.md`):

- albedo = base colour x (1 - metallic) x (1 - transmission);
- specular = base colour x metallic + (1 - metallic) x F0, with F0 the normal-incidence
  reflectance of the IOR, `((ior - 1) / (ior + 1))^2`, scaled by 2 x Specular IOR Level and
  by Specular Tint, as the Principled BSDF does;
- exponent from roughness: Blender's GGX width is alpha = roughness^2; a Beckmann /
  Blinn-Phong lobe of the same width has exponent `2 / alpha^2 - 2` about the half vector
  (Walter et al. 2007, "Microfacet Models for Refraction", Section 5.2), and a Phong lobe
  about the mirror direction is about four times wider than a Blinn-Phong lobe about the
  half vector, so exponent = `(2 / alpha^2 - 2) / 4 = 1 / (2 alpha^2) - 1/2`, clamped to
  0.01..10^6 (roughness 1 gives 0.01, GGX alpha 0.99; 0.5 gives 7.5, 0.3 gives 61, 0.2
  gives 312, 0.05 gives 80000; the upper clamp is roughness 0.027, a mirror to any
  environment map's resolution; a lower clamp of 1, alpha 0.58, left roughness-1 floors
  of the `glossy` measurement scene 0.0155 from Cycles as authored, against 0.0140). logsh reads
  such lobes from a prefiltered environment (`--glossy ggx`, the default) as the GGX
  lobe of this alpha, which is what Cycles renders.

Without markup every visible mesh-like object (mesh, curve, surface, text, metaball, and
their instances) is a blocker of `Options.spheres` spheres, except flat ones (thinner
than 2% of their size, such as a ground plane or a water surface: spheres around a plane
would swallow everything standing on it), open sheets (`geometry.is_sheet`: a bent
plane, cloth, a dome, whose inside no sphere can fill) and water-only ones; there is no
height field. Flat meshes but the ground, and sheets, still cast sun shadows: the sun
shadow maps hold them.

Every change to the scene (render settings, passes, material pass indices, a default
material on objects without one) is undone before `export` returns, so the add-on
leaves the user's file as it was, and the .blend on disk is never written.
"""
import math
import os
import shutil
import time
from dataclasses import dataclass

import bpy
import mathutils
import numpy as np

from .common import (  # noqa: F401 (GEOMETRY_TYPES and MAX_SUPERSAMPLE for the add-on's panel)
    DATA_FILTER, DATA_FILTER_WIDTH, GEOMETRY_TYPES, MAX_SUPERSAMPLE, VIEW_LAYER, ExportError, new_file,
    write_blockers, write_json)
from .exr import channel_names, read_exr_channels, write_exr
from .geometry import (
    as_rendered, camera_json, export_blockers, export_heightmap, find_ground, object_indices, sun_shadow_frame,
    terrain_moves,
    write_reflection)
from .materials import (
    check_indexed, export_lamps, find_heightfield, fit_to_passes, material_table, refuse_hair, renderable_objects,
    roughness_aovs)
from .world import environment_suns, export_world, map_sun_direction, world_keys


def frames_entry(frames):
    """scene.json's `frames` for the exported `frames` (sorted, distinct): their first and
    last, and the list of them where some between were skipped (a Frame Step, a list)."""
    start, end = frames[0], frames[-1]
    if frames == list(range(start, end + 1)):
        return {"start": start, "end": end}
    return {"start": start, "end": end, "list": list(frames)}


@dataclass
class Options:
    out: str
    # The frames: an inclusive (start, end) tuple or a list of frame numbers; None takes
    # the scene's range.
    frames: object = None
    # (width, height) in pixels; None takes the scene's output size.
    resolution: tuple = None
    # Most blocker spheres per object without `logsh_spheres` (the fit stops earlier when
    # it reaches `fit_error`).
    spheres: int = 16
    # Relative volume error at which an object's fit stops adding spheres.
    fit_error: float = 0.1
    # Name of the height field object; None uses the `logsh_heightfield` property.
    heightfield: str = None
    # Height map samples along the longer side of the terrain.
    heightmap_size: int = 256
    # Environment maps wider than this are box-filtered down (SH order 8 needs far less).
    sky_max_width: int = 1024
    # G-buffer samples per camera pixel along each axis, 1 to MAX_SUPERSAMPLE: the
    # G-buffers at this multiple of the output size, one sample at each sub-pixel centre,
    # which logsh resolves to the output size with a pixel filter.
    supersample: int = 1
    # Render Cycles' Diffuse Color and Glossy Color passes into the G-buffer, which logsh
    # reads in place of the material table's colours (module doc).
    colour_passes: bool = True
    # Export materials logsh cannot represent (module doc) with a warning each, where
    # the export otherwise stops.
    approximate: bool = False
    # Texels along the longer side of each sun's shadow map (module doc), from
    # SUN_SHADOW_RESOLUTIONS; 0 writes no maps.
    sun_shadow_resolution: int = 1024


# The sizes a sun shadow map may have along its longer side.
SUN_SHADOW_RESOLUTIONS = (64, 8192)


# ---- undoable scene changes ------------------------------------------------------------

class Changes:
    """Attribute changes recorded so that `undo` restores the scene."""

    def __init__(self):
        self._undo = []

    def set(self, owner, attribute, value):
        old = getattr(owner, attribute)
        if old != value:
            self._undo.append(lambda: setattr(owner, attribute, old))
            setattr(owner, attribute, value)

    def on_undo(self, action):
        self._undo.append(action)

    def undo(self):
        for action in reversed(self._undo):
            try:
                action()
            except ReferenceError:
                pass  # the datablock went away with the scene; nothing to restore
        self._undo.clear()


# ---- entry point -----------------------------------------------------------------------

def export(scene, options, log=print):
    """Writes `scene` into `options.out` as a format-v1 scene; returns the summary dict."""
    out = os.path.abspath(options.out)
    if os.path.exists(os.path.join(out, "scene.json")):
        raise ExportError(f"{out} already holds a scene (scene.json); choose an empty directory")
    if scene.camera is None:
        raise ExportError("the scene has no camera; set Scene > Camera")
    if options.frames is None:
        # Every frame_step-th, as Blender renders the animation.
        frames = list(range(scene.frame_start, scene.frame_end + 1, max(1, scene.frame_step)))
    elif isinstance(options.frames, tuple):
        frames = list(range(options.frames[0], options.frames[1] + 1))
    else:
        frames = sorted(set(options.frames))
    if not frames:
        raise ExportError(f"the frames {options.frames or (scene.frame_start, scene.frame_end)} are empty")
    lo, hi = SUN_SHADOW_RESOLUTIONS
    if options.sun_shadow_resolution != 0 and not lo <= options.sun_shadow_resolution <= hi:
        raise ExportError(f"sun shadow resolution {options.sun_shadow_resolution} is neither 0 (no sun shadow maps) "
                          f"nor from {lo} to {hi} texels")
    start, end = frames[0], frames[-1]
    created = not os.path.exists(out)
    os.makedirs(out, exist_ok=True)

    changes = Changes()
    frame_before = scene.frame_current
    try:
        view = export_view(scene, out, changes)
        dropped = [what for what, on in (("motion blur", scene.render.use_motion_blur),
                                         ("depth of field", scene.camera.data.dof.use_dof)) if on]
        if dropped:
            log(f"note: the G-buffers are taken without the scene's {' and '.join(dropped)}, which logsh does not "
                "model: its frames are sharp")
        view_layer = configure_render(scene, options, changes)
        lamps_by_frame = export_lamps(scene, view_layer, frames)
        lights = [dict(light) for light in lamps_by_frame[start]]
        objects, materials_of = as_rendered(scene, view_layer, renderable_objects, changes)
        terrain = find_heightfield(objects, options)
        warnings = []
        refuse_hair(objects, options, warnings)
        table, index_of = material_table(objects, materials_of, terrain, changes, options, warnings)
        textured_roughness = roughness_aovs(table, index_of, view_layer, changes) if options.colour_passes else {}
        for warning in warnings:
            log(f"warning: {warning}")
        object_index = object_indices(objects, changes)
        water = {i for i, m in table.items() if m["type"] == "water"}
        # The camera's size; the G-buffers are `supersample` times it along each axis.
        width, height = (size // options.supersample for size in output_size(scene))
        description = {
            "version": 1,
            "frames": frames_entry(frames),
            "gbuffer": "gbuffer.####.exr",
            "camera": "camera.####.json",
            "blockers": "blockers.####.json",
            "materials": {str(i): m for i, m in sorted(table.items())},
            "view": view,
        }
        scene.frame_set(start)
        lamps_before_world = len(lights)
        description["light"] = export_world(scene, out, options, log, lights)
        per_frame = {frame: {"frame": frame} for frame in frames}
        if any(lamps_by_frame[frame] != lamps_by_frame[start] for frame in frames):
            # A Sky Texture's sun (added by the bake) stays with every frame's lamps.
            baked_suns = lights[lamps_before_world:]
            for frame in frames:
                per_frame[frame]["lights"] = lamps_by_frame[frame] + baked_suns
            log(f"lamps change within frames {start}-{end}: each frame's are in frame.####.json")
        world_by_frame = {}
        for frame in frames:
            scene.frame_set(frame)
            world_by_frame[frame] = world_keys(scene)
        if any(world_by_frame[frame] != world_by_frame[start] for frame in frames):
            if "baked" in world_by_frame[start]:
                raise ExportError(f"the World changes within frames {start}-{end}, and logsh bakes it once (a Sky "
                                  "Texture, a gradient or a linked Strength): export the frames in parts, or key "
                                  "only an Environment Texture's Strength and Mapping rotation, or a constant colour")
            for frame in frames:
                per_frame[frame]["light"] = world_by_frame[frame]
            log(f"the World changes within frames {start}-{end}: each frame's Strength, rotation or colour is in "
                "frame.####.json")
        # The suns logsh will take out of the environment map, each to have a shadow map.
        map_suns = []
        if options.sun_shadow_resolution and "environment" in description["light"]:
            map_suns = environment_suns(os.path.join(out, description["light"]["environment"]))
            for direction in map_suns:
                log(f"sun in the environment map towards {[round(c, 4) for c in direction]} (the map's own frame): "
                    "its shadows come from the blocker meshes' depth map")
        if options.colour_passes:
            description["colour_passes"] = True
        if lights:
            description["lights"] = lights
            for light in lights:
                if light["type"] == "sun":
                    log(f"sun lamp: direction {[round(c, 4) for c in light['direction']]}, "
                        f"angle {light['angle']:.3g} deg, strength {light['strength']:.4g}")
                else:
                    log(f"point lamp: position {[round(c, 4) for c in light['position']]}, "
                        f"radius {light['radius']:.4g}, power {light['power']:.4g} W, "
                        f"soft falloff {'on' if light['soft_falloff'] else 'off'}")
        if water:
            description["reflection_gbuffer"] = "reflection.####.exr"
        if options.supersample > 1:
            description["supersample"] = options.supersample

        scene.frame_set(start)
        ground = as_rendered(scene, view_layer, lambda depsgraph: find_ground(objects, terrain, depsgraph, log), changes)
        if ground is not None:
            description["ground"] = {"height": float(ground[0])}
        if terrain is not None and len(frames) > 1 and terrain_moves(scene, view_layer, terrain, frames, changes):
            log(f"height field \"{terrain.name}\" moves within frames {start}-{end}: one height map per frame")
            for frame in frames:
                scene.frame_set(frame)
                spec = as_rendered(scene, view_layer, lambda depsgraph: export_heightmap(
                    terrain, depsgraph, out, options, log, f"heightmap.{frame:04d}.exr"), changes)
                if frame == start:
                    description["heightfield"] = dict(spec, heights="heightmap.####.exr")
                elif [spec["min"], spec["max"]] != [description["heightfield"]["min"],
                                                    description["heightfield"]["max"]]:
                    per_frame[frame]["heightfield"] = {"min": spec["min"], "max": spec["max"]}
            if any("heightfield" in per_frame[frame] for frame in frames):
                per_frame[start]["heightfield"] = {"min": description["heightfield"]["min"],
                                                   "max": description["heightfield"]["max"]}
            scene.frame_set(start)
        elif terrain is not None:
            description["heightfield"] = as_rendered(
                scene, view_layer, lambda depsgraph: export_heightmap(terrain, depsgraph, out, options, log), changes)
        if any(len(changes) > 1 for changes in per_frame.values()):
            description["per_frame"] = "frame.####.json"
            for frame in frames:
                write_json(new_file(out, f"frame.{frame:04d}.json"), per_frame[frame])

        fits = {}
        if len(frames) < end - start + 1:
            log(f"note: scene.json says frames {start}-{end}; only {len(frames)} of them are exported, so render "
                "those with logsh render --frames")
        for frame in frames:
            began = time.time()
            scene.frame_set(frame)
            scene.render.filepath = new_file(out, f"gbuffer.{frame:04d}.exr")
            bpy.ops.render.render(write_still=True, scene=scene.name, layer=view_layer.name)
            check_indexed(scene.render.filepath, object_index, options, warnings, log)
            if options.colour_passes and frame == frames[0]:
                fit_to_passes(scene.render.filepath, frame, table, textured_roughness, warnings, log)
            camera = camera_json(scene, frame, width, height)
            write_json(new_file(out, f"camera.{frame:04d}.json"), camera)
            sampled = dict(camera, resolution=[width * options.supersample, height * options.supersample])
            reflection = new_file(out, f"reflection.{frame:04d}.exr") if water else None

            def frame_geometry(depsgraph):
                """The frame's blockers, and its reflection G-buffer where there is water."""
                blockers = export_blockers(scene, depsgraph, objects, terrain, index_of, table, object_index, options,
                                           fits, frame, log, ground=ground and ground[1])
                if reflection:
                    write_reflection(scene, depsgraph, sampled, index_of, water, reflection)
                return blockers

            spheres, casters = as_rendered(scene, view_layer, frame_geometry, changes)
            suns = [light for light in per_frame[frame].get("lights", lights) if light["type"] == "sun"]
            rotation = per_frame[frame].get("light", description["light"]).get("rotation")
            for direction in (map_sun_direction(d, rotation) for d in map_suns):
                # A Sun lamp set along the map's sun: its map serves both (within 1 degree).
                if all(np.dot(direction, sun["direction"]) < math.cos(math.radians(0.5)) for sun in suns):
                    suns.append({"type": "sun", "direction": direction})
            shadows = None
            if options.sun_shadow_resolution and suns and casters:
                shadows = export_sun_shadows(scene, view_layer, out, frame, suns, casters, options, log)
            write_blockers(new_file(out, f"blockers.{frame:04d}.json"), frame, spheres, shadows)
            log(f"frame {frame}: {len(spheres)} blocker spheres, {time.time() - began:.1f} s")
        write_json(new_file(out, "scene.json"), description)
        if warnings:
            log(f"{len(warnings)} warning{'s' if len(warnings) > 1 else ''}: the export approximates what logsh "
                "cannot represent (above)")
    except BaseException:
        if created:
            # Only this export wrote there: leave no half-written scene behind.
            shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        changes.undo()
        scene.frame_set(frame_before)
    log(f"wrote {out}")
    return description


# ---- colour management -----------------------------------------------------------------

# The grid on which the view transform is sampled for logsh's previews: VIEW_LUT_SIZE
# values per channel, 2^t for t evenly spaced over VIEW_LUT_LOG2 (linear 1.5e-5 to 256:
# every transform Blender ships is black below and white above).
VIEW_LUT_SIZE = 33
VIEW_LUT_LOG2 = (-16.0, 8.0)


def export_view(scene, out, changes):
    """The scene's colour management as logsh's PNG previews apply it (`view` in
    scene.json): the view transform, look, exposure, gamma, display and Film > Transparent,
    and, unless it is plain Standard, the transform itself sampled through Blender's own
    `Image.save_render` on a grid of linear colours at exposure 0 (`view_lut.exr`; logsh
    applies the exposure in front of it)."""
    view, display = scene.view_settings, scene.display_settings.display_device
    description = {
        "transform": view.view_transform,
        "look": view.look,
        "exposure": float(view.exposure),
        "gamma": float(view.gamma),
        "display": display,
        "transparent": bool(scene.render.film_transparent),
    }
    if (view.view_transform, view.look, view.gamma, display) == ("Standard", "None", 1.0, "sRGB") \
            and not view.use_curve_mapping:
        return description
    n = VIEW_LUT_SIZE
    lo, hi = VIEW_LUT_LOG2
    axis = 2.0 ** np.linspace(lo, hi, n)
    # Column r + n g, row b; Blender's pixels run from the bottom row up.
    b, g, r = np.meshgrid(axis, axis, axis, indexing="ij")
    grid = np.stack([r.reshape(n, n * n), g.reshape(n, n * n), b.reshape(n, n * n), np.ones((n, n * n))], axis=-1)
    image = bpy.data.images.new("logsh view transform", n * n, n, float_buffer=True, alpha=True)
    path = new_file(out, "view_lut.png.tmp")
    try:
        image.pixels.foreach_set(grid.astype(np.float32).ravel())
        changes.set(view, "exposure", 0.0)
        settings = scene.render.image_settings
        if hasattr(settings, "media_type"):
            changes.set(settings, "media_type", "IMAGE")  # Blender 5: before file_format
        changes.set(settings, "file_format", "PNG")
        changes.set(settings, "color_depth", "16")
        changes.set(settings, "color_mode", "RGB")
        image.save_render(path, scene=scene)
        shown = bpy.data.images.load(path)
        shown.colorspace_settings.name = "Non-Color"
        values = np.empty(n * n * n * 4, dtype=np.float32)
        shown.pixels.foreach_get(values)
        bpy.data.images.remove(shown)
    finally:
        bpy.data.images.remove(image)
        if os.path.exists(path):
            os.remove(path)
    values = values.reshape(n, n * n, 4)
    write_exr(new_file(out, "view_lut.exr"), {c: values[..., k] for k, c in enumerate("RGB")})
    description["lut"] = {"file": "view_lut.exr", "size": n, "log2_range": [lo, hi]}
    return description


# ---- render settings -------------------------------------------------------------------

def rendered_view_layer(scene):
    """The view layer the export takes (and `render_cycles.py` renders): the window's
    active one where it is used for rendering, else the first."""
    return bpy.context.view_layer if bpy.context.view_layer.use else scene.view_layers[0]


def configure_render(scene, options, changes):
    """Cycles, one centred sample per pixel, the four data passes, multilayer float EXR."""
    render, cycles = scene.render, scene.cycles
    changes.set(render, "engine", "CYCLES")
    changes.set(cycles, "samples", 1)
    changes.set(cycles, "use_adaptive_sampling", False)
    changes.set(cycles, "use_denoising", False)
    changes.set(cycles, "pixel_filter_type", DATA_FILTER)
    changes.set(cycles, "filter_width", DATA_FILTER_WIDTH)
    changes.set(cycles, "max_bounces", 0)  # data passes come from the camera ray alone
    changes.set(render, "use_motion_blur", False)
    changes.set(render, "use_border", False)  # the whole frame, which the camera describes
    changes.set(render, "use_multiview", False)
    changes.set(render, "use_compositing", False)
    changes.set(render, "use_sequencer", False)
    changes.set(render, "film_transparent", False)
    for attribute in dir(render):  # no metadata (file path, date, host) in the outputs
        if attribute.startswith("use_stamp"):
            changes.set(render, attribute, False)
    if options.resolution:
        changes.set(render, "resolution_x", int(options.resolution[0]))
        changes.set(render, "resolution_y", int(options.resolution[1]))
        changes.set(render, "resolution_percentage", 100)
    if not 1 <= options.supersample <= MAX_SUPERSAMPLE:
        raise ExportError(f"supersample {options.supersample} is not from 1 to {MAX_SUPERSAMPLE}")
    if options.supersample > 1:
        width, height = output_size(scene)
        changes.set(render, "resolution_x", width * options.supersample)
        changes.set(render, "resolution_y", height * options.supersample)
        changes.set(render, "resolution_percentage", 100)
    if render.pixel_aspect_x != render.pixel_aspect_y:
        raise ExportError("pixel aspect is not 1 (Output > Format > Aspect); logsh's camera has square pixels")
    if scene.camera.type != "CAMERA":
        raise ExportError(f"the scene camera \"{scene.camera.name}\" is not a camera object")
    changes.set(scene.camera.data.dof, "use_dof", False)

    settings = render.image_settings
    if hasattr(settings, "media_type"):
        changes.set(settings, "media_type", "MULTI_LAYER_IMAGE")  # Blender 5: before file_format
    changes.set(settings, "file_format", "OPEN_EXR_MULTILAYER")
    changes.set(settings, "color_depth", "32")
    changes.set(settings, "exr_codec", "ZIP")
    changes.set(render, "use_file_extension", False)
    changes.on_undo(lambda path=render.filepath: setattr(render, "filepath", path))

    # One view layer, named as the format's default channel names expect.
    layer = rendered_view_layer(scene)
    for other in scene.view_layers:
        if other != layer:
            if other.name == VIEW_LAYER:
                changes.set(other, "name", VIEW_LAYER + ".other")
            changes.set(other, "use", False)
    changes.set(layer, "name", VIEW_LAYER)
    changes.set(layer, "use", True)
    for attribute in dir(layer):
        if attribute.startswith("use_pass_"):
            wanted = attribute in ("use_pass_position", "use_pass_normal", "use_pass_uv", "use_pass_material_index",
                                   "use_pass_object_index") or \
                (options.colour_passes and attribute in ("use_pass_diffuse_color", "use_pass_glossy_color"))
            changes.set(layer, attribute, wanted)
    for attribute in dir(layer.cycles):  # Cycles' own passes (denoising data, debug, ...)
        if attribute.startswith("use_pass_") or attribute in ("denoising_store_passes", "pass_debug_sample_count"):
            changes.set(layer.cycles, attribute, False)
    return layer


# ---- sun shadow maps -------------------------------------------------------------------

def export_sun_shadows(scene, view_layer, out, frame, suns, casters, options, log):
    """The shadow map of each of `suns` (module doc) over `casters`, the frame's blockers
    from `export_blockers`; returns blockers.####.json's `sun_shadows`, or None when the
    blockers have no outline to map."""
    points = np.concatenate([vertices for _, _, vertices in casters])
    specs = [sun_shadow_frame(sun["direction"], points, options.sun_shadow_resolution) for sun in suns]
    if any(spec is None for spec in specs):
        log(f"note: frame {frame}: the blockers have no extent across a sun; no sun shadow maps")
        return None
    entries = []
    for k, (sun, spec) in enumerate(zip(suns, specs)):
        began = time.time()
        name = f"sun_shadow.{frame:04d}.{k}.exr"
        near, far = render_depths(scene, view_layer, spec, casters, new_file(out, name + ".render"))
        write_exr(new_file(out, name), {"Z": near, "Zfar": far})
        entries.append({
            "image": name,
            "axis": list(sun["direction"]),
            "origin": [float(c) + 0.0 for c in spec["origin"]],
            "right": [float(c) + 0.0 for c in spec["right"]],
            "up": [float(c) + 0.0 for c in spec["up"]],
            "size": [float(c) for c in spec["size"]],
        })
        nx, ny = spec["texels"]
        log(f"frame {frame}: sun {k} shadow map {nx}x{ny}, texel {1000 * spec['texel']:.3g} mm, "
            f"{time.time() - began:.1f} s")
    return entries


# Blender's depth where a ray meets nothing, which the maps keep; the format reads any
# depth from NO_SURFACE up as no surface.
NO_DEPTH, NO_SURFACE = 1e10, 1e9


def render_depths(scene, view_layer, spec, casters, path):
    """The map's `Z` and `Zfar` (module doc) over the blocker objects of `casters` alone,
    rows from the top: Cycles' depth pass through an orthographic camera in the image
    plane of `spec` (`sun_shadow_frame`) looking along -axis, and through one beyond the
    farthest blocker looking back along +axis, whose first surface is the last one along
    the map's ray. Cycles' orthographic depth is the distance from the camera's plane
    along its view axis (1e10 where a ray meets nothing): the first render's is `Z` as it
    stands, the second's is turned into the distance from the map's plane and mirrored
    left to right (its camera's right is the map's left; the texel centres coincide).
    `Zfar` is at least `Z` wherever `Z` holds a surface, and 1e10 where it does not.

    Every other object that renders is disabled in renders, an instancer that is no
    blocker itself keeps its instances but not its own surface (where Blender lets it),
    and the blockers are made visible to camera rays; one plain material replaces every
    material, so that transparency and shading cannot move or hide a surface, and the World
    is taken away. The camera, the World, the resolution, the passes and the objects'
    visibility are restored before this returns, so the next G-buffer renders as if no map
    had been made."""
    changes = Changes()
    render = scene.render
    camera_data = bpy.data.cameras.new("logsh sun shadow")
    camera = bpy.data.objects.new("logsh sun shadow", camera_data)
    plain = bpy.data.materials.new("logsh sun shadow")
    try:
        scene.collection.objects.link(camera)
        nx, ny = spec["texels"]
        camera_data.type = "ORTHO"
        camera_data.sensor_fit = "AUTO"
        camera_data.ortho_scale = max(spec["size"])
        camera_data.clip_start = 0.5 * spec["gap"]
        camera_data.clip_end = spec["depth"] + spec["gap"]
        changes.set(scene, "camera", camera)
        changes.set(scene, "world", None)
        changes.set(render, "resolution_x", nx)
        changes.set(render, "resolution_y", ny)
        changes.set(render, "resolution_percentage", 100)
        changes.set(render, "use_border", False)
        changes.set(render, "filepath", path)
        changes.set(render.image_settings, "exr_codec", "NONE")
        changes.set(view_layer, "material_override", plain)
        if hasattr(view_layer, "samples"):
            changes.set(view_layer, "samples", 0)
        for attribute in dir(view_layer):
            if attribute.startswith("use_pass_"):
                changes.set(view_layer, attribute, attribute == "use_pass_z")
        blockers = {obj.name for obj, _, _ in casters}
        instancers = {parent.name for _, parent, _ in casters if parent is not None}
        for obj in scene.objects:
            if obj == camera:
                continue
            if obj.name in blockers:
                changes.set(obj, "visible_camera", True)
            elif obj.name in instancers:
                changes.set(obj, "show_instancer_for_render", False)
            elif not obj.hide_render:
                changes.set(obj, "hide_render", True)
        right, up = np.asarray(spec["right"]), np.asarray(spec["up"])
        axis = np.cross(right, up)
        behind = spec["depth"] + spec["gap"]
        views = [(right, axis, spec["origin"]), (-right, -axis, spec["origin"] - axis * behind)]
        depths = []
        for x, z, position in views:
            columns = [x, up, z, position]
            camera.matrix_world = mathutils.Matrix([[float(c[row]) for c in columns] for row in range(3)] +
                                                   [[0.0, 0.0, 0.0, 1.0]])
            bpy.ops.render.render(write_still=True, scene=scene.name, layer=view_layer.name)
            names = channel_names(path)
            wanted = [n for n in (f"{view_layer.name}.Depth.Z", "Depth.Z", "Z") if n in names]
            if not wanted:
                raise ExportError(f"{path}: Cycles wrote no depth pass (channels {', '.join(names)})")
            depths.append(read_exr_channels(path, wanted[:1])[wanted[0]])
            os.remove(path)
    finally:
        changes.undo()
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(camera_data)
        bpy.data.materials.remove(plain)
        if os.path.exists(path):
            os.remove(path)
    near, back = depths[0], depths[1][:, ::-1]
    surface = near < NO_SURFACE
    far = np.where(back < NO_SURFACE, behind - back.astype(np.float64), near).astype(np.float32)
    far = np.where(surface, np.maximum(far, near), np.float32(NO_DEPTH))
    return near, far


def output_size(scene):
    r = scene.render
    return r.resolution_x * r.resolution_percentage // 100, r.resolution_y * r.resolution_percentage // 100


