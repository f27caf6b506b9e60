"""The light of an export: the World as an environment map (written, or baked from
nodes such as a Sky Texture, with its sun found), its keyed strength and rotation, and
the Mapping node's rotation."""

import math
import os
import time

import bpy
import mathutils
import numpy as np

from .exr import read_exr_channels, write_exr
from .common import ExportError, new_file


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


# ---- suns in an environment map --------------------------------------------------------

# logsh's rule for the suns it takes out of an environment map (`src/shade/sharp_lights.rs`,
# whose constants these are): a peak at least SUN_CONTRAST times the median luminance, its
# region of texels at least REGION_FLOOR of the peak, within MAX_SUN_RADIUS of its centre
# and carrying at least MIN_SUN_SHARE of the map's power; at most MAX_SUNS suns out of
# REGIONS_TRIED regions.
SUN_CONTRAST, REGION_FLOOR, MIN_SUN_SHARE = 50.0, 0.01, 0.02
MAX_SUN_RADIUS = math.radians(10.0)
MAX_SUNS, REGIONS_TRIED = 4, 16
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def environment_suns(path):
    """The directions, in the map's own frame, of the suns logsh takes out of the
    equirectangular map at `path` (`--sharp-lights auto`), so that each gets a shadow map
    (`map_sun_direction` turns them as the World's Mapping node does). The same rule as
    logsh's; the directions agree with logsh's to the map's resampling, a fraction of a
    texel, within the tolerance a shadow map serves a sun by (1 degree)."""
    channels = read_exr_channels(path, ["R", "G", "B"])
    # Texels in f32 as logsh holds them (a residual texel too), sums in f64 as it takes them.
    rgb = np.stack([channels[c] for c in "RGB"], axis=-1).astype(np.float32)
    height, width = rgb.shape[:2]
    luminance = sum(LUMINANCE[k] * rgb[..., k].astype(np.float64) for k in range(3))
    theta = np.pi * (np.arange(height) + 0.5) / height
    phi = np.pi - 2.0 * np.pi * (np.arange(width) + 0.5) / width
    edges = np.pi * np.arange(height + 1) / height
    solid_angle = 2.0 * np.pi / width * (np.cos(edges[:-1]) - np.cos(edges[1:]))

    def direction(r, c):
        return np.stack(np.broadcast_arrays(np.sin(theta[r]) * np.cos(phi[c]), np.sin(theta[r]) * np.sin(phi[c]),
                                            np.cos(theta[r])), axis=-1)

    total = float((luminance * solid_angle[:, None]).sum())
    flat = luminance.ravel()
    median = float(np.partition(flat, flat.size // 2)[flat.size // 2])
    suns = []
    if not total > 0.0:
        return suns
    tried = np.zeros(luminance.shape, dtype=bool)
    for _ in range(REGIONS_TRIED):
        if len(suns) == MAX_SUNS:
            break
        open_luminance = np.where(tried, -np.inf, luminance)
        peak = np.unravel_index(int(np.argmax(open_luminance)), luminance.shape)
        peak_luminance = float(luminance[peak])
        if not (peak_luminance >= SUN_CONTRAST * median and peak_luminance > 0.0):
            break
        rows, columns = grow_region(luminance >= REGION_FLOOR * peak_luminance, peak)
        tried[rows, columns] = True
        # A region reaching twice MAX_SUN_RADIUS from its peak fails the radius test below
        # whatever its centre: a bright area of the sky, which can cover half the map.
        if (direction(rows, columns) @ direction(*peak)).min() < math.cos(2.0 * MAX_SUN_RADIUS):
            continue
        # The ring of texels around the region (rows clamped, columns wrapping).
        around = [((rows + dr) * width + (columns + dc) % width)[(rows + dr >= 0) & (rows + dr < height)]
                  for dr in (-1, 0, 1) for dc in (-1, 0, 1)]
        ring = np.setdiff1d(np.concatenate(around), rows * width + columns)
        background = rgb.reshape(-1, 3)[ring].astype(np.float64).mean(axis=0) if ring.size else np.zeros(3)
        above = np.clip(rgb[rows, columns].astype(np.float64) - background, 0.0, None) * solid_angle[rows, None]
        weight = above @ LUMINANCE
        directions = direction(rows, columns)
        centre = (weight[:, None] * directions).sum(axis=0)
        if not (weight.sum() / total >= MIN_SUN_SHARE and np.linalg.norm(centre) > 0.0):
            continue
        axis = centre / np.linalg.norm(centre)
        if np.arccos(np.clip(directions @ axis, -1.0, 1.0)).max() > MAX_SUN_RADIUS:
            continue
        rgb[rows, columns] = background
        luminance[rows, columns] = rgb[rows[0], columns[0]].astype(np.float64) @ LUMINANCE
        suns.append([float(c) for c in axis])
    return suns


def grow_region(mask, peak):
    """The rows and columns of the texels of `mask` 8-connected to `peak`, wrapping in
    azimuth, found a run of a row at a time (a region of millions of texels is a few
    thousand runs)."""
    height, width = mask.shape
    seen = np.zeros_like(mask)
    runs = []
    seeds = [peak]
    while seeds:
        r, c = seeds.pop()
        if seen[r, c] or not mask[r, c]:
            continue
        # The run through (r, c): out along the row both ways, at most once round.
        open_ = np.roll(mask[r] & ~seen[r], -c)
        if open_.all():
            left, right = 0, width - 1
        else:
            right = int(np.argmin(open_)) - 1
            left = int(np.argmin(open_[::-1]))
        span = np.arange(c - left, c + right + 1) % width
        seen[r, span] = True
        runs.append((r, span))
        # Runs of the rows above and below touching it, diagonals included.
        touching = np.arange(c - left - 1, c + right + 2) % width
        for rr in (r - 1, r + 1):
            if not 0 <= rr < height:
                continue
            open_ = mask[rr, touching] & ~seen[rr, touching]
            starts = np.flatnonzero(open_ & ~np.concatenate(([False], open_[:-1])))
            seeds.extend((rr, int(touching[k])) for k in starts)
    rows = np.concatenate([np.full(len(span), r) for r, span in runs])
    columns = np.concatenate([span for _, span in runs])
    return rows, columns


def map_sun_direction(direction, rotation):
    """A sun's direction `direction` in the map's frame as the World shows it behind a
    Mapping rotation `rotation` (Euler XYZ degrees, `mapping_rotation`; None for none):
    the radiance along d is the map's along R d, so the sun lies along R^T."""
    if rotation is None:
        return list(direction)
    m = mathutils.Euler([math.radians(a) for a in rotation], "XYZ").to_matrix()
    return [float(c) for c in m.transposed() @ mathutils.Vector(direction)]
