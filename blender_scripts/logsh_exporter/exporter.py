"""Exports the open Blender scene as a logsh scene (format v1, `docs/design.md`).

Used by the command line (`blender_scripts/export_scene.py`) and by the add-on's
operator (`__init__.py`); both call `export(scene, Options(...))`.

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
Material Output, with any nodes in front of them. The Principled BSDF's Transmission,
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
its own); a material out of view keeps the colours below. Without them (`colour_passes`
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
would swallow everything standing on it) and water-only ones; there is no height field.

Every change to the scene (render settings, passes, material pass indices, a default
material on objects without one) is undone before `export` returns, so the add-on
leaves the user's file as it was, and the .blend on disk is never written.
"""
import json
import math
import os
import shutil
import time
from dataclasses import dataclass

import bpy
import mathutils
import numpy as np
from mathutils.bvhtree import BVHTree

from . import blockers as blocker_fit
from .exr import read_exr_channels, write_exr

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

def new_file(out, name):
    """The path of output `name`, which must not exist yet: an export never writes over a
    file, so neither an earlier export nor an input (the .blend, an image) is lost."""
    path = os.path.join(out, name)
    if os.path.exists(path):
        raise ExportError(f"{path} exists; export into an empty directory")
    return path


def export(scene, options, log=print):
    """Writes `scene` into `options.out` as a format-v1 scene; returns the summary dict."""
    out = os.path.abspath(options.out)
    if os.path.exists(os.path.join(out, "scene.json")):
        raise ExportError(f"{out} already holds a scene (scene.json); choose an empty directory")
    if scene.camera is None:
        raise ExportError("the scene has no camera; set Scene > Camera")
    if options.frames is None:
        frames = list(range(scene.frame_start, scene.frame_end + 1))
    elif isinstance(options.frames, tuple):
        frames = list(range(options.frames[0], options.frames[1] + 1))
    else:
        frames = sorted(set(options.frames))
    if not frames:
        raise ExportError(f"the frames {options.frames or (scene.frame_start, scene.frame_end)} are empty")
    start, end = frames[0], frames[-1]
    created = not os.path.exists(out)
    os.makedirs(out, exist_ok=True)

    changes = Changes()
    frame_before = scene.frame_current
    try:
        view = export_view(scene, out, changes)
        view_layer = configure_render(scene, options, changes)
        lamps_by_frame = export_lamps(scene, view_layer, frames)
        lights = [dict(light) for light in lamps_by_frame[start]]
        objects = renderable_objects(scene, view_layer)
        terrain = find_heightfield(objects, options)
        warnings = []
        table, index_of = material_table(objects, terrain, changes, options, warnings)
        textured_roughness = roughness_aovs(table, index_of, view_layer, changes) if options.colour_passes else {}
        for warning in warnings:
            log(f"warning: {warning}")
        object_index = object_indices(objects, changes)
        water = {i for i, m in table.items() if m["type"] == "water"}
        # The camera's size; the G-buffers are `supersample` times it along each axis.
        width, height = (size // options.supersample for size in output_size(scene))
        description = {
            "version": 1,
            "frames": {"start": start, "end": end},
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
        ground = find_ground(objects, terrain, log)
        if ground is not None:
            description["ground"] = {"height": float(ground)}
        if terrain is not None and len(frames) > 1 and terrain_moves(scene, terrain, frames):
            log(f"height field \"{terrain.name}\" moves within frames {start}-{end}: one height map per frame")
            for frame in frames:
                scene.frame_set(frame)
                spec = export_heightmap(terrain, bpy.context.evaluated_depsgraph_get(), out, options, log,
                                        f"heightmap.{frame:04d}.exr")
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
            description["heightfield"] = export_heightmap(terrain, bpy.context.evaluated_depsgraph_get(), out, options, log)
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
            depsgraph = bpy.context.evaluated_depsgraph_get()
            scene.render.filepath = new_file(out, f"gbuffer.{frame:04d}.exr")
            bpy.ops.render.render(write_still=True, scene=scene.name, layer=view_layer.name)
            if options.colour_passes and frame == frames[0]:
                fit_to_passes(scene.render.filepath, frame, table, textured_roughness, warnings, log)
            camera = camera_json(scene, frame, width, height)
            write_json(new_file(out, f"camera.{frame:04d}.json"), camera)
            spheres = export_blockers(scene, depsgraph, objects, terrain, index_of, table, object_index, options, fits,
                                      frame, log)
            write_blockers(new_file(out, f"blockers.{frame:04d}.json"), frame, spheres)
            if water:
                sampled = dict(camera, resolution=[width * options.supersample, height * options.supersample])
                write_reflection(scene, depsgraph, sampled, index_of, water, new_file(out, f"reflection.{frame:04d}.exr"))
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
    layer = bpy.context.view_layer if bpy.context.view_layer.use else scene.view_layers[0]
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


def output_size(scene):
    r = scene.render
    return r.resolution_x * r.resolution_percentage // 100, r.resolution_y * r.resolution_percentage // 100


# ---- objects and materials -------------------------------------------------------------

LAMP_NAMES = {"SUN": "Sun", "POINT": "Point", "SPOT": "Spot", "AREA": "Area"}


def export_lamps(scene, view_layer, frames):
    """The lamps that light the render on each of `frames`, as scene.json's `lights`
    ({frame: lights}): each Sun lamp becomes a `sun` (direction towards it, Blender's
    Angle, Strength and Color), each Point lamp a `point` (world position, Radius, Power,
    Color, Soft Falloff), as it is on that frame: a keyed lamp moves, fades or turns from
    frame to frame. Any other lamp, or a setting logsh cannot represent, stops the export,
    naming the lamp: a lamp left out would make every frame silently too dark."""
    names = {o.name for o in view_layer.objects}
    lamps = []
    for obj in scene.objects:
        if obj.type != "LIGHT" or obj.hide_render or obj.name not in names:
            continue
        lamp = obj.data
        if lamp.energy <= 0.0 and not _keyed(lamp):
            continue
        kind = LAMP_NAMES.get(lamp.type, lamp.type.title())
        if lamp.type not in ("SUN", "POINT"):
            article = "an" if kind[:1] in "AEIOU" else "a"
            raise ExportError(f"light \"{obj.name}\" is {article} {kind} lamp; logsh shades Sun and Point lamps and the "
                              "World only. Replace it with a Sun or Point lamp, or disable it in renders (Object "
                              "Properties > Visibility) or set its Power to 0")
        unsupported = [
            (getattr(lamp, "use_nodes", False), "uses nodes; logsh reads its Strength or Power and Color only. "
                                                "Switch Use Nodes off"),
            (getattr(lamp, "use_temperature", False), "takes its colour from Temperature; logsh reads Color only. "
                                                      "Switch Temperature off and set the Color"),
            (not getattr(lamp, "use_shadow", True), "has Cast Shadow off; logsh shadows every lamp. Switch Cast "
                                                    "Shadow on"),
            (getattr(lamp, "diffuse_factor", 1.0) != 1.0 or getattr(lamp, "specular_factor", 1.0) != 1.0,
             "has a Diffuse or Specular influence other than 1; logsh lights both fully. Set them to 1"),
            (lamp.type == "POINT" and not getattr(lamp, "normalize", True),
             "has Normalize off; logsh reads Power as Blender does with Normalize on. Switch Normalize on"),
            (not getattr(obj, "visible_diffuse", True) or not getattr(obj, "visible_glossy", True),
             "is hidden from Diffuse or Glossy rays (Object Properties > Visibility > Ray Visibility); logsh "
             "lights both. Switch them on"),
        ]
        for refused, why in unsupported:
            if refused:
                raise ExportError(f"{kind} lamp \"{obj.name}\" {why}")
        lamps.append(obj)
    if not lamps:
        return {frame: [] for frame in frames}
    by_frame = {}
    for frame in frames:
        scene.frame_set(frame)
        by_frame[frame] = [lamp_json(obj) for obj in lamps]
    # A lamp dark on every frame lights nothing.
    lit = [any(by_frame[f][i]["strength" if "strength" in by_frame[f][i] else "power"] > 0.0 for f in frames)
           for i in range(len(lamps))]
    return {f: [light for light, on in zip(lights, lit) if on] for f, lights in by_frame.items()}


def _keyed(datablock):
    """Whether `datablock` has animation data (keys or drivers) that may change it."""
    animation = getattr(datablock, "animation_data", None)
    return animation is not None and (animation.action is not None or len(animation.drivers) > 0)


def lamp_json(obj):
    """One lamp as scene.json's `lights` holds it, at the current frame."""
    lamp = obj.data
    # Blender's Exposure scales the lamp's Strength or Power by 2^Exposure.
    energy = float(lamp.energy) * 2.0 ** float(getattr(lamp, "exposure", 0.0))
    color = [float(c) for c in lamp.color]
    if lamp.type == "SUN":
        axis = (obj.matrix_world.to_3x3() @ mathutils.Vector((0.0, 0.0, 1.0))).normalized()
        return {
            "type": "sun",
            "direction": [float(axis.x), float(axis.y), float(axis.z)],
            "angle": max(math.degrees(getattr(lamp, "angle", 0.0)), 1e-3),
            "strength": energy,
            "color": color,
        }
    return {
        "type": "point",
        "position": [float(c) for c in obj.matrix_world.translation],
        "radius": float(getattr(lamp, "shadow_soft_size", 0.0)),
        "power": energy,
        "color": color,
        "soft_falloff": bool(getattr(lamp, "use_soft_falloff", True)),
    }


def renderable_objects(scene, view_layer):
    """Geometry objects that render in this view layer, and the sources of instances
    (collection instances, particles, geometry nodes), which render through their
    instancer even when they are not in the view layer themselves."""
    names = {o.name for o in view_layer.objects}
    direct = [o for o in scene.objects if o.type in GEOMETRY_TYPES and o.name in names and not o.hide_render]
    instanced = []
    for instance in bpy.context.evaluated_depsgraph_get().object_instances:
        source = instance.object.original
        if instance.is_instance and source.type in GEOMETRY_TYPES and source not in direct and source not in instanced:
            instanced.append(source)
    return direct + instanced


def find_heightfield(objects, options):
    if options.heightfield:
        match = [o for o in objects if o.name == options.heightfield]
        if not match:
            raise ExportError(f"no visible geometry object named \"{options.heightfield}\" for the height field")
        return match[0]
    marked = [o for o in objects if o.get("logsh_heightfield")]
    if len(marked) > 1:
        raise ExportError("several objects have logsh_heightfield set: " + ", ".join(o.name for o in marked) + "; keep one")
    return marked[0] if marked else None


def material_table(objects, terrain, changes, options, warnings):
    """Gives every material on a renderable object its own pass index 1..N and returns
    the table (index -> format-v1 material) and the map material name -> index; what a
    material holds that logsh cannot represent stops the export, or with
    `options.approximate` is appended to `warnings`."""
    default = None
    used = {}
    for obj in objects:
        slots = obj.material_slots
        if obj.type == "MESH" and not any(s.material for s in slots):
            if default is None:
                default = bpy.data.materials.new("logsh default")
                changes.on_undo(lambda m=default: bpy.data.materials.remove(m))
            if len(slots) == 0:
                obj.data.materials.append(default)
                changes.on_undo(lambda data=obj.data: data.materials.pop())
            else:
                for slot in slots:
                    changes.set(slot, "material", default)
        for slot in obj.material_slots:
            if slot.material is not None:
                used.setdefault(slot.material.name, (slot.material, set()))[1].add(obj == terrain)

    table, index_of = {}, {}
    for i, name in enumerate(sorted(used), start=1):
        material, on_terrain = used[name]
        if on_terrain == {True, False}:
            raise ExportError(f"material \"{name}\" is on the height field and on other objects; give the terrain its own material")
        changes.set(material, "pass_index", i)
        table[i] = convert_material(material, on_terrain == {True}, options.colour_passes,
                                    lambda problem: refuse(problem, options, warnings), warnings.append)
        index_of[name] = i
    return table, index_of


ROUGHNESS_AOV = "logsh_roughness"


def roughness_aovs(table, index_of, view_layer, changes):
    """For every `phong` material whose Roughness is driven by nodes, an AOV Output node
    (`ROUGHNESS_AOV`) fed by what drives it, and the view layer's AOV of that name, both
    removed again by `changes`; returns index -> (name, socket value) of those materials.
    Textures and everything else in front of the socket then arrive as Blender evaluates
    them, in the G-buffer's `ViewLayer.logsh_roughness.X`, which `fit_to_passes` reads."""
    textured = {}
    for name, i in index_of.items():
        material = bpy.data.materials[name]
        node = _principled(material)
        if table[i]["type"] != "phong" or node is None or not _linked(node, "Roughness"):
            continue
        tree = material.node_tree
        aov = tree.nodes.new("ShaderNodeOutputAOV")
        aov.aov_name = ROUGHNESS_AOV
        changes.on_undo(lambda tree=tree, aov=aov: tree.nodes.remove(aov))
        tree.links.new(node.inputs["Roughness"].links[0].from_socket, aov.inputs["Value"])
        textured[i] = (name, float(node.inputs["Roughness"].default_value))
    if textured and ROUGHNESS_AOV not in view_layer.aovs:
        added = view_layer.aovs.add()
        added.name, added.type = ROUGHNESS_AOV, "VALUE"
        changes.on_undo(lambda: view_layer.aovs.remove(view_layer.aovs[ROUGHNESS_AOV]))
    return textured


def _read_first(gbuffer, alternatives):
    """The channels of the first of `alternatives` (lists of full channel names: Blender
    5's, then Blender 4's) that `gbuffer` holds, in their order."""
    for names in alternatives:
        try:
            channels = read_exr_channels(gbuffer, names)
            return [channels[name] for name in names]
        except ValueError:
            continue
    raise ExportError(f"{gbuffer}: Blender wrote none of {alternatives[0]}")


def fit_to_passes(gbuffer, frame, table, textured, warnings, log):
    """What the table takes from Blender's own evaluation in the first frame's G-buffer:

    - each material of `textured` (from `roughness_aovs`) the lobe width of its pixels:
      the root mean square of their roughness, so that the mean of GGX's alpha =
      roughness^2 is kept (logsh shades one lobe width per material; each is a warning
      that says the width chosen);
    - every material in view its mean Diffuse Color as `albedo` and mean Glossy Color as
      `specular`, which logsh uses only for the points seen in water's reflection (the
      G-buffer's passes colour the rest), in place of the sockets' unlinked values; a
      mean that is black keeps the table's colour, which says whether a lobe is shaded."""
    index, = _read_first(gbuffer, [["ViewLayer.Material Index.X"], ["ViewLayer.IndexMA.X"]])
    index = np.rint(index).astype(int)
    passes = []
    for blender5, blender4 in (("Diffuse Color", "DiffCol"), ("Glossy Color", "GlossCol")):
        passes.append(np.stack(_read_first(gbuffer, [[f"{VIEW_LAYER}.{name}.{c}" for c in "RGB"]
                                                     for name in (blender5, blender4)]), axis=-1))
    for i, entry in table.items():
        pixels = index == i
        if entry["type"] == "water" or not pixels.any():
            continue
        for key, values in (("albedo", passes[0]), ("specular", passes[1])):
            mean = values[pixels].mean(axis=0)
            if key in entry and mean.max() > 0.0:
                entry[key] = [float(c) for c in mean]
    if not textured:
        return
    roughness, = _read_first(gbuffer, [[f"{VIEW_LAYER}.{ROUGHNESS_AOV}.X"]])
    for i, (name, unlinked) in sorted(textured.items()):
        values = roughness[index == i]
        if values.size == 0:
            warnings.append(f"material \"{name}\": its Roughness is driven by nodes and it is not in view at frame "
                            f"{frame}; logsh shades it with roughness {unlinked:.3g}, the socket's own value")
        else:
            fitted = float(np.sqrt(np.mean(np.clip(values, 0.0, 1.0) ** 2)))
            table[i]["exponent"] = phong_exponent(fitted)
            warnings.append(f"material \"{name}\": its Roughness is driven by nodes (from {float(values.min()):.3g} "
                            f"to {float(values.max()):.3g} over its {values.size} pixels at frame {frame}); logsh "
                            f"shades one lobe width per material, roughness {fitted:.3g}")
        log(f"warning: {warnings[-1]}")


def _principled(material):
    """The BSDF node feeding the active Material Output, if it is one we read."""
    tree = material.node_tree
    if tree is None or not getattr(material, "use_nodes", True):  # Blender 4 without nodes
        return None
    outputs = [n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output] or \
              [n for n in tree.nodes if n.type == "OUTPUT_MATERIAL"]
    if not outputs or not outputs[0].inputs["Surface"].is_linked:
        return None
    return outputs[0].inputs["Surface"].links[0].from_node


def _value(node, name, fallback):
    socket = node.inputs.get(name)
    if socket is None:
        return fallback
    v = socket.default_value
    return list(v)[:3] if hasattr(v, "__len__") else float(v)


def _linked(node, name):
    socket = node.inputs.get(name)
    return socket is not None and socket.is_linked


def refuse(problem, options, warnings):
    """Stops the export on `problem`, or with `options.approximate` records it."""
    if not options.approximate:
        raise ExportError(f"{problem}; logsh cannot shade it (export with --approximate to leave it out with a "
                          "warning)")
    warnings.append(problem)


def unrepresentable(material, node, kind, colour_passes):
    """What `node`, the surface of `material`, holds that logsh cannot shade: a list of
    sentences naming the material and the node (module doc)."""
    where = f"material \"{material.name}\": {node.bl_label} \"{node.name}\""
    if node.type not in SURFACE_NODES:
        return [f"material \"{material.name}\": its surface is a {node.bl_label} node (\"{node.name}\"), not a "
                "Principled, Diffuse or Glossy BSDF"]
    if node.type != "BSDF_PRINCIPLED":
        return []
    problems = []
    layers = [("Subsurface Weight", "subsurface"), ("Sheen Weight", "sheen"), ("Coat Weight", "coat")]
    if kind != "water":
        layers.insert(0, ("Transmission Weight", "transmission"))
    for socket, what in layers:
        if _linked(node, socket):
            problems.append(f"{where} has a linked {socket} ({what})")
        elif _value(node, socket, 0.0) > NEGLIGIBLE_WEIGHT:
            problems.append(f"{where} has {what} ({socket} {_value(node, socket, 0.0):.3g} > {NEGLIGIBLE_WEIGHT})")
    if kind == "water" and colour_passes and (_linked(node, "Transmission Weight") or
                            _value(node, "Transmission Weight", 0.0) < 1.0 - NEGLIGIBLE_WEIGHT) and \
            (_linked(node, "Metallic") or _value(node, "Metallic", 0.0) < 1.0 - NEGLIGIBLE_WEIGHT):
        problems.append(f"{where} is water with a diffuse layer (Transmission Weight "
                        f"{_value(node, 'Transmission Weight', 0.0):.3g}); logsh shades water as its reflection alone "
                        "(set Transmission Weight to 1)")
    colour, strength = _value(node, "Emission Color", [0.0] * 3), _value(node, "Emission Strength", 0.0)
    if _linked(node, "Emission Strength") or (_linked(node, "Emission Color") and strength > 0.0) or \
            strength * max(colour) > 0.0:
        problems.append(f"{where} emits light (Emission Strength {strength:.3g})")
    return problems


def phong_exponent(roughness):
    """Phong exponent about the mirror direction for a GGX roughness (module doc)."""
    alpha = max(roughness, 1e-3) ** 2
    return float(min(max(1.0 / (2.0 * alpha * alpha) - 0.5, MIN_EXPONENT), MAX_EXPONENT))


def convert_material(material, on_terrain, colour_passes, refuse, warn):
    """The format-v1 entry of `material` (module doc); `refuse(problem)` is told what it
    holds that logsh cannot shade, `warn(problem)` what logsh approximates."""
    node = _principled(material)
    base, metallic, roughness, transmission = list(material.diffuse_color)[:3], material.metallic, material.roughness, 0.0
    ior, level, tint = 1.5, 0.5, [1.0, 1.0, 1.0]
    if node is not None and node.type == "BSDF_PRINCIPLED":
        base = _value(node, "Base Color", base)
        metallic = _value(node, "Metallic", metallic)
        roughness = _value(node, "Roughness", roughness)
        transmission = _value(node, "Transmission Weight", 0.0)
        ior = _value(node, "IOR", ior)
        level = _value(node, "Specular IOR Level", level)
        tint = _value(node, "Specular Tint", tint)
        if not isinstance(tint, list):
            tint = [tint] * 3
    elif node is not None and node.type == "BSDF_DIFFUSE":
        base, metallic = _value(node, "Color", base), 0.0
        roughness = 1.0
    elif node is not None and node.type in ("BSDF_GLOSSY", "BSDF_ANISOTROPIC"):
        base, metallic = _value(node, "Color", base), 1.0
        roughness = _value(node, "Roughness", 0.5)

    kind = material.get("logsh_type")
    principled = node is not None and node.type == "BSDF_PRINCIPLED"
    if colour_passes and principled and (on_terrain or kind in (None, "diffuse", "phong")):
        # Its specular layer, weighed per pixel by the Glossy Color pass; on the terrain
        # too, which logsh shades by where it is, whatever its material's type.
        kind = "phong"
    elif on_terrain:
        kind = "heightfield"
    elif kind is None:
        kind = "phong" if metallic >= 0.5 or roughness < 0.4 else "diffuse"
    kind = str(kind)
    if kind not in MATERIAL_TYPES:
        raise ExportError(f"material \"{material.name}\": logsh_type \"{kind}\" is not one of {', '.join(MATERIAL_TYPES)}")
    if node is not None:
        for problem in unrepresentable(material, node, kind, colour_passes):
            refuse(problem)
        if kind == "phong" and _linked(node, "Roughness") and not colour_passes:
            warn(f"material \"{material.name}\": its Roughness is driven by nodes; logsh shades one lobe width per "
                 f"material, that of roughness {roughness:.3g}")
        if not colour_passes:
            for socket in ("Base Color", "Color", "Metallic", "IOR", "Specular IOR Level", "Specular Tint"):
                if _linked(node, socket):
                    warn(f"material \"{material.name}\": its {socket} is driven by nodes; without colour passes "
                         f"its unlinked value is exported")
    colour = [max(float(c), 0.0) for c in base]
    if kind in ("diffuse", "heightfield"):
        return {"type": kind, "albedo": colour}
    if kind == "water":
        tint_prop = material.get("logsh_tint")
        return {"type": "water", "tint": [float(c) for c in tint_prop][:3] if tint_prop is not None else colour}
    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2 * 2.0 * level
    diffuse_weight = (1.0 - metallic) * (1.0 - transmission)
    albedo = [c * diffuse_weight for c in colour]
    specular = [c * metallic + (1.0 - metallic) * f0 * t for c, t in zip(colour, tint)]
    if colour_passes and node is not None:
        # A black colour tells logsh to leave the lobe out: only where no node can make
        # the pass non-zero.
        driven = lambda *sockets: any(_linked(node, s) for s in sockets)  # noqa: E731
        if max(albedo) <= 0.0 and driven("Base Color", "Color", "Metallic", "Transmission Weight"):
            albedo = [1e-3] * 3
        if max(specular) <= 0.0 and driven("Base Color", "Color", "Metallic", "Specular IOR Level", "Specular Tint",
                                           "IOR"):
            specular = [1e-3] * 3
    return {"type": "phong", "albedo": albedo, "specular": specular, "exponent": phong_exponent(roughness)}


# ---- geometry --------------------------------------------------------------------------

def world_triangles(obj_eval, matrix):
    """(T, 3, 3) world-space triangles of an evaluated object, or None without geometry."""
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
    return world[tris.reshape(-1, 3)]


def triangle_tree(triangles):
    """Blender's BVH over (T, 3, 3) triangles, for nearest-point and ray queries."""
    vertices = triangles.reshape(-1, 3)
    return BVHTree.FromPolygons([tuple(v) for v in vertices], [(3 * i, 3 * i + 1, 3 * i + 2) for i in range(len(triangles))])


def is_flat(triangles):
    points = triangles.reshape(-1, 3)
    centred = points - points.mean(axis=0)
    extents = np.sort(np.ptp(centred @ np.linalg.svd(centred, full_matrices=False)[2].T, axis=0))
    return extents[-1] <= 0 or extents[0] < FLAT_THICKNESS * extents[-1]


def find_ground(objects, terrain, log):
    """The height of the scene's floor, when there is no height field: the lowest flat,
    horizontal mesh whose extent covers every other object's in x and y (an object may set
    the custom property `logsh_ground` to false to be left out). logsh then treats it as
    an infinite plane hiding the lower hemisphere from everything above it, as Cycles'
    floor hides it; without this a constant or bright-bottomed World would light the
    undersides of objects from below the floor."""
    if terrain is not None:
        return None
    depsgraph = bpy.context.evaluated_depsgraph_get()
    bounds = {}
    for obj in objects:
        if obj.type not in GEOMETRY_TYPES or obj.is_instancer:
            continue
        evaluated = obj.evaluated_get(depsgraph)
        triangles = world_triangles(evaluated, evaluated.matrix_world)
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
        return best[0]
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


def export_blockers(scene, depsgraph, objects, terrain, index_of, table, object_index, options, fits, frame, log):
    """Spheres of every blocker object at this frame; prints each fit's error."""
    allowed = {o.name for o in objects}
    spheres, reports = [], []
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
        if fit == "skip":
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
                if is_flat(triangles):
                    fits[key] = "skip"
                    log(f"note: \"{original.name}\" is flat; not a blocker (set its logsh_spheres property to force it)")
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
    report_fit_errors(reports, frame, log)
    return spheres


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
    triangles = world_triangles(terrain.evaluated_get(depsgraph), terrain.evaluated_get(depsgraph).matrix_world)
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


def terrain_moves(scene, terrain, frames):
    """Whether the terrain's evaluated surface differs between `frames`: anything that
    moves it (an animated transform, modifiers such as Wave or Ocean, shape keys,
    armatures, geometry nodes) shows in its world-space triangles. Compared to 1e-6 of its
    extent, far below a height map's spacing."""
    first = None
    for frame in frames:
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = terrain.evaluated_get(depsgraph)
        triangles = world_triangles(evaluated, evaluated.matrix_world)
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
        raise ExportError(f"camera \"{obj.name}\" is {data.type}; logsh reads perspective cameras only")
    if data.shift_x != 0.0 or data.shift_y != 0.0:
        raise ExportError(f"camera \"{obj.name}\" has a lens shift; logsh's camera has none")
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


# ---- light -----------------------------------------------------------------------------

def world_source(scene):
    """How the World lights the scene at the current frame: `("constant", rgb)`, `("bake",
    what, sky)` for what logsh takes from a bake (a Sky Texture, a gradient, a linked
    strength), or `("environment", background, texture)`."""
    world = scene.world
    if world is None:
        raise ExportError("the scene has no World; add one (World tab) for the light")
    tree = world.node_tree
    if tree is None or not getattr(world, "use_nodes", True):
        return "constant", [float(c) for c in world.color]
    outputs = [n for n in tree.nodes if n.type == "OUTPUT_WORLD" and n.is_active_output] or \
              [n for n in tree.nodes if n.type == "OUTPUT_WORLD"]
    if not outputs or not outputs[0].inputs["Surface"].is_linked:
        return "constant", [0.0, 0.0, 0.0]
    background = outputs[0].inputs["Surface"].links[0].from_node
    if background.type != "BACKGROUND":
        raise ExportError(f"the World's surface is a {background.bl_label} node; logsh reads a Background node "
                          "with a constant colour or an Environment Texture")
    colour = background.inputs["Color"]
    texture = colour.links[0].from_node if colour.is_linked else None
    if background.inputs["Strength"].is_linked or (texture is not None and texture.type != "TEX_ENVIRONMENT"):
        what = texture.bl_label if texture is not None else "linked Strength"
        sky = texture if texture is not None and texture.type == "TEX_SKY" else None
        return "bake", what, sky
    if texture is None:
        strength = float(background.inputs["Strength"].default_value)
        return "constant", [float(c) * strength for c in list(colour.default_value)[:3]]
    return "environment", background, texture


def world_keys(scene):
    """What of the World logsh follows from frame to frame, at the current frame, as a
    frame's `light` in scene.json's `per_frame` holds it: a constant World's colour times
    its Strength, or an Environment Texture's Strength and its Mapping rotation. For a
    World logsh bakes, every value of its node tree instead, so that a change is seen."""
    source = world_source(scene)
    if source[0] == "constant":
        return {"constant": source[1]}
    if source[0] == "environment":
        background, texture = source[1], source[2]
        rotation = [0.0, 0.0, 0.0]
        if texture.inputs["Vector"].is_linked:
            rotation = mapping_rotation(texture.inputs["Vector"].links[0].from_node)
        return {"strength": float(background.inputs["Strength"].default_value), "rotation": rotation}
    values = []
    for node in scene.world.node_tree.nodes:
        for socket in node.inputs:
            value = getattr(socket, "default_value", None)
            values.append(repr(list(value)) if hasattr(value, "__len__") else repr(value))
    return {"baked": values}


def export_world(scene, out, options, log, lights):
    """The World as a format-v1 light: an environment map or a constant colour; a Sky
    Texture's sun is appended to `lights` (`bake_world`)."""
    source = world_source(scene)
    if source[0] == "constant":
        return {"constant": source[1]}
    if source[0] == "bake":
        # A Sky Texture, a gradient, a linked strength: what Cycles renders of the World.
        return bake_world(scene, scene.world, out, options, source[1], log, source[2], lights)
    background, texture = source[1], source[2]
    strength = float(background.inputs["Strength"].default_value)
    rotation = None
    if texture.inputs["Vector"].is_linked:
        rotation = mapping_rotation(texture.inputs["Vector"].links[0].from_node)
    if texture.projection != "EQUIRECTANGULAR":
        projection = texture.bl_rna.properties["projection"].enum_items[texture.projection].name
        raise ExportError(f"the World's Environment Texture uses {projection} projection; logsh reads Equirectangular")
    image = texture.image
    if image is None or image.size[0] == 0:
        raise ExportError("the World's Environment Texture has no (loadable) image")
    w, h = image.size
    pixels = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    rgb = pixels.reshape(h, w, 4)[::-1, :, :3]  # Blender stores images bottom-up
    if not image.is_float and image.colorspace_settings.name == "sRGB":
        rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    factor = 1
    while w // factor > options.sky_max_width and h % (2 * factor) == 0 and w % (2 * factor) == 0:
        factor *= 2
    if factor > 1:
        rgb = rgb.reshape(h // factor, factor, w // factor, factor, 3).mean(axis=(1, 3))
        log(f"environment map {w}x{h} box-filtered to {w // factor}x{h // factor}")
    write_exr(new_file(out, "sky.exr"), {c: rgb[..., k] for k, c in enumerate("RGB")})
    light = {"environment": "sky.exr", "strength": strength}
    if rotation is not None and any(abs(r) > 1e-9 for r in rotation):
        light["rotation"] = rotation
        log(f"environment map rotated by {[round(r, 3) for r in rotation]} deg (Euler XYZ, the Mapping node's)")
    return light


BAKE_SAMPLES = 64


# The window around a Sky Texture's sun rendered again to measure it (`sun_of`): pixels
# along each side, samples per pixel, and its half-width beyond the disc's radius.
SUN_WINDOW_PIXELS, SUN_WINDOW_SAMPLES, SUN_WINDOW_MARGIN = 96, 256, math.radians(1.0)


def bake_world(scene, world, out, options, what, log, sky=None, lights=None):
    """Renders `world` alone into an equirectangular map (`sky.exr`, options.sky_max_width
    wide) with Cycles and a panoramic camera looking along +X with +Z up, which is the
    Environment Texture's orientation; the map carries the World's strength.

    A Sky Texture `sky` whose sun disc is on is baked without its disc, and the sun, what
    the disc adds, is appended to `lights` as a `sun` of Blender's Sun Size (`sun_of`).
    Baked into the map, a disc of half a degree spread over a few texels and the pixel
    filter's tail, and its 64 samples a texel measured it 3 % dim (a white floor under
    Blender's default sky 7.02 where Cycles renders 7.24, with exact visibility)."""
    width = min(options.sky_max_width, 2048)
    bake = bpy.data.scenes.new("logsh world bake")
    camera_data = bpy.data.cameras.new("logsh world bake")
    camera = bpy.data.objects.new("logsh world bake", camera_data)
    with_disc = sky is not None and sky.sky_type in ("SINGLE_SCATTERING", "MULTIPLE_SCATTERING", "NISHITA") and \
        sky.sun_disc and lights is not None
    temporary = []
    try:
        bake.world = world
        bake.collection.objects.link(camera)
        bake.camera = camera
        camera_data.type = "PANO"
        camera_data.panorama_type = "EQUIRECTANGULAR"
        camera.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
        bake.render.engine = "CYCLES"
        bake.cycles.use_denoising = False
        bake.render.resolution_percentage = 100
        bake.render.film_transparent = False
        bake.render.image_settings.file_format = "OPEN_EXR"
        bake.render.image_settings.color_depth = "32"
        bake.render.image_settings.exr_codec = "ZIP"
        bake.render.use_file_extension = False

        def panorama(path, size, samples, latitudes=(-math.pi / 2, math.pi / 2), longitudes=(-math.pi, math.pi)):
            camera_data.latitude_min, camera_data.latitude_max = latitudes
            camera_data.longitude_min, camera_data.longitude_max = longitudes
            bake.render.resolution_x, bake.render.resolution_y = size
            bake.cycles.samples = samples
            bake.render.filepath = path
            bpy.ops.render.render(write_still=True, scene=bake.name)

        began = time.time()
        whole_map = dict(size=(width, width // 2), samples=BAKE_SAMPLES)
        if not with_disc:
            panorama(new_file(out, "sky.exr"), **whole_map)
        else:
            window = sun_window(sky)
            temporary = [new_file(out, f"sky_sun_{k}.tmp.exr") for k in ("with", "without")]
            panorama(temporary[0], **window)
            sky.sun_disc = False
            try:
                panorama(new_file(out, "sky.exr"), **whole_map)
                panorama(temporary[1], **window)
            finally:
                sky.sun_disc = True
    finally:
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(camera_data)
        bpy.data.scenes.remove(bake)
    try:
        log(f"World ({what}) baked by Cycles into a {width}x{width // 2} map, {BAKE_SAMPLES} samples, "
            f"{time.time() - began:.1f} s")
        if with_disc:
            sun = sun_of(*temporary, window["latitudes"], window["longitudes"], math.degrees(sky.sun_size))
            if sun is None:
                log("the Sky Texture's sun adds no light (below the horizon)")
            else:
                lights.append(sun)
                log(f"sun of the Sky Texture: direction {[round(c, 4) for c in sun['direction']]}, angle "
                    f"{sun['angle']:.3g} deg, strength {sun['strength']:.4g}, shaded as a sun outside the map")
    finally:
        for path in temporary:
            if os.path.exists(path):
                os.remove(path)
    return {"environment": "sky.exr", "strength": 1.0}


def sun_window(sky):
    """The panorama (`bake_world`'s) of the window around the Sky Texture `sky`'s sun
    disc, in the map's latitude and longitude (`sun_of`). The sun lies towards (cos e sin
    r, cos e cos r, sin e) for Sun Elevation e and Sun Rotation r (measured: the disc's
    centroid in a whole bake, rotation 40 and elevation 35 degrees, at azimuth 50.0 and
    elevation 35.0)."""
    latitude = sky.sun_elevation
    longitude = math.atan2(-math.cos(sky.sun_rotation), math.sin(sky.sun_rotation))
    half = sky.sun_size / 2.0 + SUN_WINDOW_MARGIN
    half_longitude = min(math.pi, half / max(math.cos(latitude), 1e-3))
    return dict(
        size=(SUN_WINDOW_PIXELS, SUN_WINDOW_PIXELS),
        samples=SUN_WINDOW_SAMPLES,
        latitudes=(latitude - half, latitude + half),
        longitudes=(longitude - half_longitude, longitude + half_longitude),
    )


def sun_of(with_sun, without_sun, latitudes, longitudes, angle):
    """The sun that the panorama `with_sun` holds beyond `without_sun`, both of the window
    `latitudes` x `longitudes` (radians, in the map's coordinates: row 0 at the window's
    highest latitude, longitude -phi of Cycles' equirectangular direction): a format-v1
    `sun` of diameter `angle` degrees whose irradiance on a surface facing it is the
    difference's, towards its power-weighted mean direction; None where the difference
    holds no light."""
    names = ["R", "G", "B"]
    a, b = read_exr_channels(with_sun, names), read_exr_channels(without_sun, names)
    height, width = a["R"].shape
    (lat0, lat1), (lon0, lon1) = latitudes, longitudes
    latitude = lat1 - (np.arange(height) + 0.5) / height * (lat1 - lat0)
    longitude = lon0 + (np.arange(width) + 0.5) / width * (lon1 - lon0)
    # Cycles' equirectangular_to_direction (src/scene/light.rs): phi = -longitude.
    lat, lon = np.meshgrid(latitude, longitude, indexing="ij")
    directions = np.stack([np.cos(lat) * np.cos(lon), -np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    solid_angle = ((lon1 - lon0) / width) * ((lat1 - lat0) / height) * np.cos(lat)
    power = [np.clip(a[c] - b[c], 0.0, None) * solid_angle for c in names]
    irradiance = [float(p.sum()) for p in power]
    strength = max(irradiance)
    if not strength > 0.0:
        return None
    weight = sum(power)
    mean = (directions * weight[..., None]).sum(axis=(0, 1))
    direction = mean / np.linalg.norm(mean)
    return {
        "type": "sun",
        "direction": [float(c) for c in direction],
        "angle": max(float(angle), 1e-3),
        "strength": strength,
        "color": [c / strength for c in irradiance],
    }


def mapping_rotation(node):
    """The rotation a Mapping node applies to the World's Environment Texture, as Euler XYZ
    degrees of a Point-type mapping (the map looked up along R d); a Texture-type mapping is
    the inverse. Anything that changes directions otherwise (location, non-uniform scale,
    drivers, another input than Texture Coordinate > Generated) stops the export."""
    if node.type != "MAPPING":
        raise ExportError(f"the World's Environment Texture Vector comes from a {node.bl_label} node; logsh reads "
                          "a Mapping node (rotation only) fed by Texture Coordinate > Generated, or nothing")
    source = node.inputs["Vector"]
    if not source.is_linked or source.links[0].from_node.type != "TEX_COORD" or \
            source.links[0].from_socket.name != "Generated":
        raise ExportError("the World's Mapping node must take its Vector from Texture Coordinate > Generated")
    kind = node.vector_type
    for name in ("Location", "Rotation", "Scale"):
        socket = node.inputs.get(name)
        if socket is not None and socket.enabled and socket.is_linked:
            raise ExportError(f"the World's Mapping node has its {name} linked; logsh reads constant values")
    location = node.inputs.get("Location")
    if kind in ("POINT", "TEXTURE") and location is not None and any(abs(v) > 1e-9 for v in location.default_value):
        raise ExportError("the World's Mapping node has a Location; it would bend directions (logsh reads rotation only)")
    scale = node.inputs.get("Scale")
    if scale is not None:
        s = list(scale.default_value)
        if not (s[0] > 0 and abs(s[0] - s[1]) < 1e-6 and abs(s[0] - s[2]) < 1e-6):
            raise ExportError(f"the World's Mapping node has a non-uniform or negative Scale {s}; logsh reads rotation only")
    euler = mathutils.Euler(node.inputs["Rotation"].default_value, "XYZ")
    if kind == "TEXTURE":
        euler = euler.to_matrix().inverted().to_euler("XYZ")
    return [math.degrees(a) for a in euler]


def write_blockers(path, frame, spheres):
    """One sphere per line: hundreds of blockers stay small and readable."""
    lines = ",\n".join("  " + json.dumps(s) for s in spheres)
    with open(path, "w") as f:
        f.write(f'{{"frame": {frame}, "spheres": [\n{lines}\n]}}\n')


def write_json(path, value):
    with open(path, "w") as f:
        json.dump(value, f, indent=1)
        f.write("\n")
