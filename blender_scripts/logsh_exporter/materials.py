"""The objects and materials of an export: which objects render, the height-field
object, the lamps, the material table and its conversions from Blender's nodes, and the
shader AOVs that carry a Principled BSDF's roughness (the conventions are in
`exporter.py`'s module doc)."""

import math

import bpy
import mathutils
import numpy as np

from .exr import read_exr_channels
from .common import (
    ExportError, GEOMETRY_TYPES, MATERIAL_TYPES, MAX_EXPONENT, MIN_EXPONENT, NEGLIGIBLE_WEIGHT, SURFACE_NODES, VIEW_LAYER)


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


def renderable_objects(depsgraph):
    """Geometry objects that render, in the scene evaluated as Cycles renders it
    (`geometry.as_rendered`): those of the view layer that render, then the sources of
    instances (collection instances, particles, geometry nodes), which render through
    their instancer even when they are not in the view layer themselves; and per object
    the materials its rendered geometry carries, which Geometry Nodes may have set (Set
    Material) beyond its slots."""
    direct, instanced, materials_of = [], [], {}
    for instance in depsgraph.object_instances:
        source = instance.object.original
        if source.type not in GEOMETRY_TYPES:
            continue
        if not instance.is_instance and source not in direct:
            direct.append(source)
        elif instance.is_instance and source not in instanced:
            instanced.append(source)
        data = getattr(instance.object, "data", None)
        carried = materials_of.setdefault(source.name, set())
        carried.update(m.original.name for m in getattr(data, "materials", ()) if m is not None)
        carried.update(slot.material.original.name for slot in instance.object.material_slots if slot.material)
    return direct + [o for o in instanced if o not in direct], materials_of


def refuse_hair(objects, options, warnings):
    """Hair (a hair particle system that renders its strands, or a Curves object) renders
    in Cycles as strands that logsh fits no spheres to and shades as unshadowed surfaces:
    refused, or with `options.approximate` a warning."""
    for obj in objects:
        if obj.type == "CURVES":
            refuse(f"object \"{obj.name}\" is hair (a Curves object): it would cast no shadow", options, warnings)
        for modifier in obj.modifiers:
            if modifier.type != "PARTICLE_SYSTEM" or not modifier.show_render:
                continue
            settings = modifier.particle_system.settings
            if settings.type == "HAIR" and settings.render_type == "PATH":
                refuse(f"object \"{obj.name}\" has hair (particle system \"{modifier.particle_system.name}\"): "
                       "its strands would cast no shadow", options, warnings)


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


def material_table(objects, materials_of, terrain, changes, options, warnings):
    """Gives every material on a renderable object, in its slots or set on its rendered
    geometry (`materials_of`, from `renderable_objects`), its own pass index 1..N and
    returns the table (index -> format-v1 material) and the map material name -> index;
    what a material holds that logsh cannot represent stops the export, or with
    `options.approximate` is appended to `warnings`."""
    default = None
    used = {}
    for obj in objects:
        slots = obj.material_slots
        empty = [slot for slot in slots if slot.material is None]
        if (obj.type == "MESH" and len(slots) == 0) or empty:
            # Faces with no material, which Cycles renders with its default surface: given
            # that surface as a material for the export, so that they have an index and
            # are not taken for the background.
            if default is None:
                default = cycles_default_surface()
                changes.on_undo(lambda m=default: bpy.data.materials.remove(m))
            if len(slots) == 0:
                obj.data.materials.append(default)
                changes.on_undo(lambda data=obj.data: data.materials.pop())
            for slot in empty:
                changes.set(slot, "material", default)
        for slot in obj.material_slots:
            if slot.material is not None:
                used.setdefault(slot.material.name, (slot.material, set()))[1].add(obj == terrain)
        for name in materials_of.get(obj.name, ()):
            used.setdefault(name, (bpy.data.materials[name], set()))[1].add(obj == terrain)

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


def cycles_default_surface():
    """A material that renders as Cycles renders a face with none: a new material, whose
    Principled BSDF (base colour 0.8, roughness 0.5, IOR 1.5) gives the same Diffuse and
    Glossy Color passes as Cycles' default surface (0.763 and 0.046 seen head on)."""
    return bpy.data.materials.new("logsh default")


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


def check_indexed(gbuffer, object_index, options, warnings, log):
    """Pixels of an object that carry no material index: geometry its Geometry Nodes or
    particles made without a material, which Cycles renders with its default surface and
    logsh would take for the background. Refused per object, or with
    `options.approximate` a warning (logsh then shows the environment there)."""
    objects, = _read_first(gbuffer, [[f"{VIEW_LAYER}.Object Index.X"], [f"{VIEW_LAYER}.IndexOB.X"]])
    material, = _read_first(gbuffer, [[f"{VIEW_LAYER}.Material Index.X"], [f"{VIEW_LAYER}.IndexMA.X"]])
    bare = np.rint(objects[np.rint(material) == 0]).astype(int)
    names = {i: name for name, i in object_index.items()}
    for i, count in zip(*np.unique(bare[bare > 0], return_counts=True)):
        refuse(f"object \"{names.get(int(i), f'with index {i}')}\": {count} pixels of its rendered geometry have no "
               "material (made by Geometry Nodes or particles without one: give it one, with a Set Material node), "
               "and would show as background", options, warnings)
        log(f"warning: {warnings[-1]}")


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
    entry = {"type": "phong", "albedo": albedo, "specular": specular, "exponent": phong_exponent(roughness)}
    if colour_passes and node is not None:
        # A black colour tells logsh to leave the lobe out: only where no node can make
        # the pass non-zero.
        driven = lambda *sockets: any(_linked(node, s) for s in sockets)  # noqa: E731
        if max(albedo) <= 0.0 and driven("Base Color", "Color", "Metallic", "Transmission Weight"):
            entry["albedo"] = [1e-3] * 3
        if max(specular) <= 0.0 and driven("Base Color", "Color", "Metallic", "Specular IOR Level", "Specular Tint",
                                           "IOR"):
            entry["specular"] = [1e-3] * 3
        fresnel = fresnel_at_normal_incidence(node, specular, metallic)
        if fresnel is not None:
            entry["fresnel"] = fresnel
    return entry


def fresnel_at_normal_incidence(node, specular, metallic):
    """The reflectance at normal incidence of `node`'s specular layer, which the Glossy
    Color pass cannot tell logsh (module doc): a Glossy BSDF has no Fresnel term (1); a
    Principled BSDF's is its converted `specular` (the IOR's, times 2 x Specular IOR Level
    and Specular Tint, mixed with the base colour by Metallic), averaged over R, G and B.
    None where a node drives it, and logsh works it out from the pass."""
    if node.type in ("BSDF_GLOSSY", "BSDF_ANISOTROPIC"):
        return 1.0
    if node.type != "BSDF_PRINCIPLED":
        return None
    if any(_linked(node, s) for s in ("Metallic", "IOR", "Specular IOR Level", "Specular Tint")) or \
            (metallic > 0.0 and _linked(node, "Base Color")):
        return None
    return float(min(max(sum(specular) / 3.0, 0.0), 1.0))
