"""logsh as a Blender render engine: Render Properties > Render Engine > logsh.

F12 renders the current frame, Ctrl+F12 and `blender -b file.blend -E LOGSH -a` the
frame range, `-f N` one frame:

1. The G-buffers are taken the way the exporter takes them (`exporter.py`). Blender does
   not let an engine start a render from inside its own, so a child process does it: the
   scene and what it uses are written to a temporary .blend (`bpy.data.libraries.write`,
   image paths made absolute), which the child opens and exports with the same
   `exporter.export` as File > Export.
2. `logsh render` shades the exported frames into multi-layer EXRs.
3. Each frame's beauty becomes the Combined pass of the Render Result, and every logsh
   pass (diffuse, specular, environment, indirect, the visibility terms) a render pass of
   its own (`PASSES`), which the compositor's Render Layers node offers.

A sequence is exported and shaded as a whole on its first frame, so that what does not
change between frames is done once: the exporter bakes the sky once and reads every
frame in one child, and one `logsh render` keeps its kernel tables, prefiltered maps and
the pyramid's plan from frame to frame. The later frames only read their EXR. The work
directory is removed when the render completes or is cancelled.

Errors (an Area lamp, a material logsh cannot shade, no logsh binary) go to Blender's
report and stop the render with the exporter's message, which names the object.
Progress and cancelling go through `update_progress` and `test_break`.

The logsh binary is, in this order: `LOGSH_BINARY` in the environment, the add-on's
preference, the one the extension zip carries (`bin/logsh`), or `logsh` on PATH.
"""
import json
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
import time

import bpy
import numpy as np

from . import exr

ENGINE = "LOGSH"

# logsh's EXR layers and the render passes they become: (layer, pass name, channels).
PASSES = (
    ("diffuse", "Diffuse", "RGB"),
    ("specular", "Specular", "RGB"),
    ("environment", "Environment", "RGB"),
    ("indirect", "Indirect", "RGB"),
    ("indirect_heightfield", "Indirect Height Field", "RGB"),
    ("indirect_blockers", "Indirect Blockers", "RGB"),
    ("visibility", "Visibility", "X"),
    ("visibility_heightfield", "Visibility Height Field", "X"),
    ("visibility_blockers", "Visibility Blockers", "X"),
)


class EngineError(Exception):
    """Something that stops a frame; the message says what and where."""


# ---- settings --------------------------------------------------------------------------

class LogshRenderSettings(bpy.types.PropertyGroup):
    """logsh's settings of a scene (`scene.logsh`), stored in the .blend."""

    quality: bpy.props.EnumProperty(
        name="Quality",
        items=[("draft", "Draft", "Order 3, table-lookup exponentiation, 8 azimuths: fastest"),
               ("default", "Default", "Order 4, quadrature exponentiation, 16 azimuths"),
               ("high", "High", "Order 6, 24 azimuths"),
               ("ultra", "Ultra", "Order 8, 32 azimuths: most accurate")],
        default="default")
    sharp_lights: bpy.props.EnumProperty(
        name="Sharp Lights",
        items=[("auto", "Auto", "Take the suns out of an environment map and shade them as sharp lights"),
               ("off", "Off", "Keep the whole environment in spherical harmonics")],
        default="auto")
    bounces: bpy.props.EnumProperty(
        name="Bounce Light",
        items=[("quality", "From Quality", "Light bounced off the ground, the terrain and the blockers, as "
                                               "many bounces as the quality preset takes"),
               ("1", "1", "One bounce"), ("2", "2", "Two bounces"), ("3", "3", "Three bounces"),
               ("0", "Off", "Direct light only")],
        default="quality")
    supersample: bpy.props.IntProperty(
        name="Supersample", default=1, min=1, max=4,
        description="G-buffer samples per pixel along each axis, resolved to anti-aliased pixels")
    pixel_filter: bpy.props.EnumProperty(
        name="Pixel Filter",
        items=[("box", "Box", "The mean of the pixel's samples"),
               ("blackman-harris", "Blackman-Harris", "Blender's default filter, 1.5 px wide")],
        default="box")
    device: bpy.props.EnumProperty(
        name="Device",
        items=[("auto", "Auto", "A hardware GPU where there is one, else the CPU"),
               ("cpu", "CPU", "Every core of the CPU"),
               ("gpu", "GPU", "Any GPU adapter, software ones included")],
        default="auto")
    colour_passes: bpy.props.BoolProperty(
        name="Materials as Evaluated", default=True,
        description="Shade textures and the Principled BSDF's layers as Cycles evaluates them "
                    "(its Diffuse Color and Glossy Color passes)")
    transfer: bpy.props.BoolProperty(
        name="Transfer Layers", default=False,
        description="Keep logsh's EXRs with transfer layers in the directory below, for logsh relight and "
                    "logsh view")
    transfer_directory: bpy.props.StringProperty(
        name="Directory", subtype="DIR_PATH", default="//logsh/")


class LogshPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    binary: bpy.props.StringProperty(
        name="logsh binary", subtype="FILE_PATH",
        description="The logsh program; empty: the one in the extension, else logsh on PATH")

    def draw(self, context):
        self.layout.prop(self, "binary")


class RENDER_PT_logsh(bpy.types.Panel):
    bl_label = "logsh"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        settings = context.scene.logsh
        for name in ("quality", "sharp_lights", "bounces", "supersample", "pixel_filter", "device",
                     "colour_passes", "transfer"):
            layout.prop(settings, name)
        if settings.transfer:
            layout.prop(settings, "transfer_directory")


# ---- the engine ------------------------------------------------------------------------

class LogshRenderEngine(bpy.types.RenderEngine):
    bl_idname = ENGINE
    bl_label = "logsh"
    bl_use_postprocess = True
    bl_use_preview = False

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for _, name, channels in PASSES:
            self.register_pass(scene, renderlayer, name, len(channels), channels,
                               "VALUE" if len(channels) == 1 else "COLOR")

    def render(self, depsgraph):
        scene = depsgraph.scene
        frame = scene.frame_current
        try:
            if scene.render.use_border:
                raise EngineError("logsh renders whole frames: turn off Render Region (Output Properties > Format)")
            job = _job_for(self, scene, depsgraph.view_layer)
            path = job.shaded(self, frame)
            if path is None:
                return  # cancelled
            self._write_result(scene, depsgraph.view_layer, path)
        except EngineError as e:
            _drop_job()
            self.report({"ERROR"}, str(e))
            self.error_set(str(e))

    def _write_result(self, scene, view_layer, path):
        width, height = _output_size(scene)
        layers = exr.channel_names(path)
        wanted = ["R", "G", "B", "A"] + [f"{layer}.{c}" for layer, _, channels in PASSES
                                         for c in (["Y"] if channels == "X" else list(channels))
                                         if f"{layer}.{c}" in layers]
        values = exr.read_exr_channels(path, wanted)
        shape = values["R"].shape
        if shape != (height, width):
            raise EngineError(f"{path}: {shape[1]}x{shape[0]} pixels where the render is {width}x{height}")

        def fill(render_pass, names):
            # Blender's passes run from the bottom row up; EXR rows from the top down.
            pixels = np.stack([values[n][::-1] for n in names], axis=-1).astype(np.float32)
            render_pass.rect.foreach_set(pixels.ravel())

        for _, name, channels in PASSES:
            self.add_pass(name, len(channels), channels, layer=view_layer.name)
        result = self.begin_result(0, 0, width, height, layer=view_layer.name)
        layer = result.layers[0]
        fill(layer.passes.find_by_name("Combined", ""), ["R", "G", "B", "A"])
        for source, name, channels in PASSES:
            names = [f"{source}.{c}" for c in (["Y"] if channels == "X" else list(channels))]
            render_pass = layer.passes.find_by_name(name, "")
            if render_pass is not None and all(n in values for n in names):
                fill(render_pass, names)
        self.end_result(result)


def _output_size(scene):
    r = scene.render
    return r.resolution_x * r.resolution_percentage // 100, r.resolution_y * r.resolution_percentage // 100


# ---- one render's work: the export and the shading -------------------------------------

class Job:
    """The frames of one render (a sequence's whole range, or one frame), exported and
    shaded into a temporary directory."""

    def __init__(self, key, scene, frames):
        self.key = key
        self.frames = frames
        self.settings = scene.logsh
        self.directory = tempfile.mkdtemp(prefix="logsh-render-")
        self.scene_name = scene.name
        self.binary = None
        self.done = False

    def output(self, frame):
        return os.path.join(self.directory, "shaded", f"render.{frame:04d}.exr")

    def shaded(self, engine, frame):
        """The EXR of `frame`, exporting and shading the job's frames the first time;
        None when the user cancelled."""
        if frame not in self.frames:
            raise EngineError(f"frame {frame} is not among the frames being rendered")
        if not self.done:
            self.binary = logsh_binary()  # before the export, which takes longer
            if not self._export(engine) or not self._shade(engine):
                return None
            self.done = True
        path = self.output(frame)
        if not os.path.isfile(path):
            raise EngineError(f"logsh wrote no output for frame {frame}")
        return path

    def _export(self, engine):
        copy = os.path.join(self.directory, "scene.blend")
        scene = bpy.data.scenes[self.scene_name]
        bpy.data.libraries.write(copy, {scene}, path_remap="ABSOLUTE", fake_user=True)
        settings = self.settings
        options = {
            "out": os.path.join(self.directory, "export"),
            "frames": self.frames,
            "supersample": settings.supersample,
            "colour_passes": settings.colour_passes,
        }
        package = os.path.dirname(os.path.abspath(__file__))
        code = _CHILD_EXPORT.format(parent=os.path.dirname(package), package=os.path.basename(package),
                                    blend=copy, scene=self.scene_name, options=json.dumps(options))
        engine.update_stats("logsh", f"exporting {len(self.frames)} frame(s)")
        if bpy.app.binary_path and os.path.isfile(bpy.app.binary_path):
            command = [bpy.app.binary_path, "-b", "--factory-startup", "--python-expr", code]
        else:  # Blender as a Python module (pip's bpy): the same interpreter.
            command = [sys.executable, "-c", code]
        return _run(engine, command, "export", lambda line: None, progress=(0.0, 0.5))

    def _shade(self, engine):
        settings = self.settings
        command = [self.binary, "render", os.path.join(self.directory, "export"),
                   "--out", os.path.join(self.directory, "shaded"),
                   "--frames", ",".join(str(f) for f in self.frames),
                   "--progress", "json", "--colour-type", "float",
                   "--quality", settings.quality, "--sharp-lights", settings.sharp_lights,
                   "--pixel-filter", settings.pixel_filter, "--device", settings.device]
        if settings.bounces != "quality":
            command += ["--bounces", settings.bounces]
        if settings.transfer:
            command.append("--transfer")
        failures = []

        def on_line(line):
            try:
                event = json.loads(line)
            except ValueError:
                return
            if event.get("event") == "frame":
                engine.update_progress(0.5 + 0.5 * (event.get("index", 0) + 1) / max(event.get("total", 1), 1))
                engine.update_stats("logsh", f"shaded frame {event.get('frame')}")
                if event.get("status") == "failed":
                    failures.append(f"frame {event.get('frame')}: {event.get('error')}")

        finished = _run(engine, command, "logsh render", on_line, progress=None)
        if failures:
            raise EngineError("logsh render: " + "; ".join(failures))
        if finished and settings.transfer:
            target = bpy.path.abspath(settings.transfer_directory)
            os.makedirs(target, exist_ok=True)
            for frame in self.frames:
                shutil.copy2(self.output(frame), os.path.join(target, f"render.{frame:04d}.exr"))
        return finished

    def close(self):
        shutil.rmtree(self.directory, ignore_errors=True)


# The child's script: open the copy, export its scene, print `error: ...` and exit 1 when
# the exporter refuses it.
_CHILD_EXPORT = """
import json, sys
sys.path.insert(0, {parent!r})
import bpy
from {package}.exporter import ExportError, Options, export
if bpy.data.filepath != {blend!r}:
    bpy.ops.wm.open_mainfile(filepath={blend!r}, load_ui=False)
scene = bpy.data.scenes[{scene!r}]
if bpy.context.window is not None:
    bpy.context.window.scene = scene
options = json.loads({options!r})
try:
    export(scene, Options(**options), log=lambda line: print(line, flush=True))
except ExportError as e:
    print("error: " + str(e), file=sys.stderr, flush=True)
    sys.exit(1)
"""


def _run(engine, command, what, on_line, progress):
    """Runs `command`, feeding each line of its standard output to `on_line`, polling
    `test_break`; False when the user cancelled. A failure raises with its last `error:`
    line (or its last lines)."""
    log = tempfile.TemporaryFile(mode="w+")
    try:
        child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=log, text=True)
    except OSError as e:
        raise EngineError(f"{what}: cannot start {command[0]}: {e}")
    lines = queue.Queue()
    reader = threading.Thread(target=lambda: [lines.put(line) for line in child.stdout], daemon=True)
    reader.start()
    started = time.monotonic()
    while child.poll() is None or reader.is_alive() or not lines.empty():
        try:
            on_line(lines.get(timeout=0.05).rstrip("\n"))
        except queue.Empty:
            pass
        if engine.test_break():
            child.kill()
            child.wait()
            return False
        if progress is not None:
            # The export reports no fraction: its share creeps towards its end.
            elapsed = time.monotonic() - started
            engine.update_progress(progress[0] + (progress[1] - progress[0]) * elapsed / (elapsed + 10.0))
    if child.returncode != 0:
        log.seek(0)
        text = log.read().strip().splitlines()
        errors = [line[len("error: "):] for line in text if line.startswith("error: ")]
        raise EngineError(f"{what}: " + (errors[-1] if errors else " / ".join(text[-3:]) or
                                         f"exited with status {child.returncode}"))
    return True


_JOB = None


def _job_for(engine, scene, view_layer):
    """The running job when it covers this render (a sequence's later frames), else a new
    one: the whole range for an animation render, the current frame otherwise."""
    global _JOB
    if engine.is_animation:
        frames = list(range(scene.frame_start, scene.frame_end + 1, max(scene.frame_step, 1)))
    else:
        frames = [scene.frame_current]
    s = scene.logsh
    key = (bpy.data.filepath, scene.name, view_layer.name, tuple(frames), _output_size(scene),
           tuple(getattr(s, name) for name in s.__annotations__))
    if _JOB is not None and _JOB.key == key and engine.is_animation:
        return _JOB
    _drop_job()
    _JOB = Job(key, scene, frames)
    return _JOB


@bpy.app.handlers.persistent
def _drop_job(*_):
    global _JOB
    if _JOB is not None:
        _JOB.close()
        _JOB = None


def logsh_binary():
    """The logsh program (module doc); an error saying where it was looked for."""
    candidates = [os.environ.get("LOGSH_BINARY", "")]
    addon = bpy.context.preferences.addons.get(__package__)
    if addon is not None and addon.preferences is not None:
        candidates.append(bpy.path.abspath(addon.preferences.binary))
    carried = os.path.join(os.path.dirname(os.path.abspath(__file__)), "bin", "logsh")
    if os.path.isfile(carried) and not os.access(carried, os.X_OK):
        # Extensions are unpacked with Python's zipfile, which keeps no file modes.
        os.chmod(carried, os.stat(carried).st_mode | 0o755)
    candidates.append(carried)
    for path in candidates:
        if path and os.path.isfile(path) and os.access(path, os.X_OK):
            return path
    found = shutil.which("logsh")
    if found:
        return found
    raise EngineError("no logsh binary: set its path in the add-on's preferences (Edit > Preferences > "
                      "Add-ons > logsh), set LOGSH_BINARY, or put logsh on PATH")


# ---- registration ----------------------------------------------------------------------

CLASSES = (LogshRenderSettings, LogshPreferences, RENDER_PT_logsh, LogshRenderEngine)


def _compatible_panels():
    """Blender's own panels that work for any engine (output, format, frame range, colour
    management): shown for logsh too."""
    for name in ("RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output", "RENDER_PT_color_management",
                 "DATA_PT_lens", "DATA_PT_camera", "DATA_PT_light", "DATA_PT_EEVEE_light",
                 "WORLD_PT_context_world", "MATERIAL_PT_preview"):
        panel = getattr(bpy.types, name, None)
        if panel is not None and hasattr(panel, "COMPAT_ENGINES"):
            yield panel


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.logsh = bpy.props.PointerProperty(type=LogshRenderSettings)
    for panel in _compatible_panels():
        panel.COMPAT_ENGINES.add(ENGINE)
    for handlers in (bpy.app.handlers.render_complete, bpy.app.handlers.render_cancel):
        if _drop_job not in handlers:
            handlers.append(_drop_job)


def unregister():
    _drop_job()
    for handlers in (bpy.app.handlers.render_complete, bpy.app.handlers.render_cancel):
        if _drop_job in handlers:
            handlers.remove(_drop_job)
    for panel in _compatible_panels():
        panel.COMPAT_ENGINES.discard(ENGINE)
    del bpy.types.Scene.logsh
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
