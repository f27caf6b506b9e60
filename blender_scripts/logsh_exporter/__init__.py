"""logsh for Blender, as an extension (Blender 4.2 and later): a render engine and an
exporter.

The render engine (`engine.py`) appears as "logsh" in Render Properties > Render Engine;
F12, Ctrl+F12 and `blender -b file.blend -E LOGSH -a` render with it, and its settings
sit in the Render Properties' logsh panel.

File > Export > logsh scene (format v1) writes a scene directory for the command line.
The operator sets up Cycles' data passes, renders every frame of the chosen range and
writes G-buffers, reflection G-buffers, blockers and their sun shadow maps, cameras, the
height map, the material table and the light into a directory, with the same code the
command line uses (`exporter.py`; its top comment documents the scene markup and the
conversions). Render settings are restored afterwards.

Install: zip this folder (`blender --command extension build` inside it, or any zip of
the folder), then Edit > Preferences > Get Extensions > Install from Disk.
"""
import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from . import engine, exporter


_ITEMS = []  # Blender keeps no reference to dynamic enum strings: Python must (bpy.props docs)


def _heightfield_items(self, context):
    _ITEMS[:] = [("", "(marked with logsh_heightfield, or none)", "")]
    _ITEMS.extend((o.name, o.name, "") for o in context.scene.objects if o.type in exporter.GEOMETRY_TYPES)
    return _ITEMS


class LOGSH_OT_export_scene(bpy.types.Operator, ExportHelper):
    """Export the scene's frames as a logsh scene directory (format v1)"""

    bl_idname = "export_scene.logsh"
    bl_label = "Export logsh scene"
    bl_options = {"PRESET"}

    # ExportHelper asks for a file name; the scene is written into a directory of that name.
    filename_ext = ""
    use_filter_folder = True
    filepath: StringProperty(subtype="DIR_PATH")

    use_scene_frames: BoolProperty(name="Scene frame range", default=True)
    frame_start: IntProperty(name="Start", default=1)
    frame_end: IntProperty(name="End", default=1)
    use_scene_resolution: BoolProperty(name="Scene resolution", default=True)
    width: IntProperty(name="Width", default=480, min=1)
    height: IntProperty(name="Height", default=270, min=1)
    spheres: IntProperty(name="Most spheres per object", default=exporter.Options.spheres, min=1,
                         description="Most blocker spheres for objects without a logsh_spheres property")
    fit_error: FloatProperty(name="Fit error", default=exporter.Options.fit_error, min=0.01, max=0.99,
                             description="Relative volume error at which an object's sphere fit stops")
    heightfield: bpy.props.EnumProperty(name="Height field", items=_heightfield_items)
    heightmap_size: IntProperty(name="Height map size", default=exporter.Options.heightmap_size, min=2)
    supersample: IntProperty(name="Supersample", default=1, min=1, max=exporter.MAX_SUPERSAMPLE,
                             description="G-buffer samples per pixel along each axis, which logsh resolves "
                                         "to anti-aliased outputs")
    colour_passes: BoolProperty(name="Colour passes", default=True,
                                description="Render the Diffuse Color and Glossy Color passes, so that logsh shades "
                                            "textures and the Principled BSDF's layers as Blender evaluates them")
    approximate: BoolProperty(name="Approximate", default=False,
                              description="Export materials logsh cannot represent (transmission, subsurface, "
                                          "emission, other shaders) with a warning each, where the export stops")
    sun_shadow_resolution: IntProperty(name="Sun shadow resolution", default=exporter.Options.sun_shadow_resolution,
                                       min=0, max=exporter.SUN_SHADOW_RESOLUTIONS[1],
                                       description="Texels along the longer side of each sun's shadow map of the "
                                                   f"blockers, {exporter.SUN_SHADOW_RESOLUTIONS[0]} or more; "
                                                   "0 writes none")

    def invoke(self, context, event):
        self.frame_start, self.frame_end = context.scene.frame_start, context.scene.frame_end
        return super().invoke(context, event)

    def execute(self, context):
        options = exporter.Options(
            out=bpy.path.abspath(self.filepath),
            frames=None if self.use_scene_frames else (self.frame_start, self.frame_end),
            resolution=None if self.use_scene_resolution else (self.width, self.height),
            spheres=self.spheres,
            fit_error=self.fit_error,
            heightfield=self.heightfield or None,
            heightmap_size=self.heightmap_size,
            supersample=self.supersample,
            colour_passes=self.colour_passes,
            approximate=self.approximate,
            sun_shadow_resolution=self.sun_shadow_resolution,
        )
        try:
            exporter.export(context.scene, options, log=lambda line: self.report({"INFO"}, line))
        except exporter.ExportError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "use_scene_frames")
        if not self.use_scene_frames:
            row = layout.row(align=True)
            row.prop(self, "frame_start")
            row.prop(self, "frame_end")
        layout.prop(self, "use_scene_resolution")
        if not self.use_scene_resolution:
            row = layout.row(align=True)
            row.prop(self, "width")
            row.prop(self, "height")
        layout.prop(self, "spheres")
        layout.prop(self, "fit_error")
        layout.prop(self, "heightfield")
        layout.prop(self, "heightmap_size")
        layout.prop(self, "supersample")
        layout.prop(self, "colour_passes")
        layout.prop(self, "approximate")
        layout.prop(self, "sun_shadow_resolution")


def _menu(self, context):
    self.layout.operator(LOGSH_OT_export_scene.bl_idname, text="logsh scene (format v1)")


def register():
    bpy.utils.register_class(LOGSH_OT_export_scene)
    bpy.types.TOPBAR_MT_file_export.append(_menu)
    engine.register()


def unregister():
    engine.unregister()
    bpy.types.TOPBAR_MT_file_export.remove(_menu)
    bpy.utils.unregister_class(LOGSH_OT_export_scene)
