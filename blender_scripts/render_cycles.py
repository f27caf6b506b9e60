"""Renders one frame of a .blend in Cycles as a truth logsh is compared against
(`examples/cycles_compare.rs`): by default the truth for the method (direct light on the
exporter's converted materials); with `--as-authored`, the truth for the user (the
.blend's materials untouched).

    python blender_scripts/render_cycles.py --blend scene.blend --out DIR [--frame 1]
        [--samples 256] [--resolution WxH] [--seed 0] [--ladder 1,2,4,... [--ladder-denoise]]
        [--as-authored] [--bounces N|default] [--denoise]
    blender -b scene.blend -P blender_scripts/render_cycles.py -- --out DIR ...

Writes `DIR/cycles.NNNN.exr` (linear RGB, half float) and `DIR/cycles.NNNN.png` (sRGB,
Standard view transform); with `--as-authored`, `DIR/authored.NNNN.exr` and `.png`;
with `--bounces N` other than 0, `cycles_bN` or `authored_bN` (`_bdefault` for Blender's
own light paths); refuses to write over any of them.

The three truths: `cycles` (converted materials, direct light) is the truth for the
method; `cycles_bdefault` (converted materials, Blender's light paths) isolates bounce
light from materials; `authored_bdefault` is what the user renders.

`--as-authored` renders the .blend as its author would, but for what must match the
G-buffer: materials, World and lamps untouched, each pixel sampled at its centre (as
below), the Standard view transform, no motion blur or depth of field. `--bounces N`
sets Cycles' max bounces (0: direct light only, the measure of materials alone);
`default` keeps the file's light paths (bounce light included, what the user renders).
On converted materials, `--bounces` other than 0 likewise keeps (or sets) the light
paths instead of the direct-light settings below.
`--denoise` runs OpenImageDenoise on the result (with its albedo and normal passes), the
user's alternative at a few samples.

With `--ladder`, times Cycles instead (`examples/cycles_timing.rs` reads the results):
one render of 1 sample first, untimed, so that loading Cycles' kernels is not counted,
then one render per sample count of the ladder, each timed from the render call to its
return (scene sync included, as every frame of a sequence pays it), written as
`DIR/cycles.NNNN.sN.exr`, and the times as `DIR/cycles.NNNN.timing.json`.
`--ladder-denoise` then times the user's alternative, OpenImageDenoise at a few samples:
each sample count of the ladder up to 16 again, denoised (`use_denoising`, OpenImageDenoise
on the CPU at Blender's default quality, input passes RGB + albedo + normal), once with the
`ACCURATE` prefilter of the albedo and normal passes and once with `FAST`, written as
`DIR/cycles.NNNN.sN.oidn_accurate.exr` and `.oidn_fast.exr`. Each is timed like the
plain rungs, from the render call to its return: the denoise runs inside the render call
and is counted. One denoised 1-sample render comes first, untimed, so that loading
OpenImageDenoise is not counted either. The JSON keeps its keys (`warm_up_seconds`,
`samples`, `seconds`: the plain ladder) and adds `oidn_warm_up_seconds`, `oidn_quality`
and `oidn`, a list of `{"name": "oidn_accurate", "prefilter": "ACCURATE", "samples": [..],
"seconds": [..]}`, one per prefilter.

So that the two renders differ only in how they compute light and visibility, every
material is first converted as the exporter converts it (`logsh_exporter/exporter.py`)
and turned back into the Cycles shader that means the same thing:

- `diffuse`, `heightfield`: a Diffuse BSDF with the albedo;
- `phong`: Diffuse BSDF (albedo) + Glossy BSDF (GGX, specular colour, the roughness whose
  mapped exponent is the exported one). GGX and the Phong lobe have the same width but
  not the same shape, and neither has a Fresnel term here;
- `water`: a sharp Glossy BSDF with the tint (a mirror), which needs one glossy bounce:
  scenes with water render with max bounces 1, glossy bounces 1 and no diffuse,
  transmission or volume bounces; scenes without water with max bounces 0. A glossy
  surface in a scene with water therefore also mirrors the direct light of other
  surfaces, which logsh (visibility only) does not.

The World is used as it is (the same light logsh reads). Each pixel's samples are taken
at its centre (box filter of width 0.01 px), as for the G-buffer, so the two images
compare pixel for pixel (a Gaussian of width 0.01 px: Cycles' box filter is one pixel wide
whatever its width, so a box of 0.01 px averaged each pixel over its whole area); no
denoising, no clamping. `--filter box1` or `--filter
blackman-harris` render with a 1-px box or Blender's default 1.5-px Blackman-Harris
instead: the truth for a supersampled export that logsh resolves with the same filter.
"""
import argparse
import json
import os
import sys
import time

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from export_scene import size  # noqa: E402
from logsh_exporter.exporter import DATA_FILTER, DATA_FILTER_WIDTH, Changes, material_table, find_heightfield, Options, \
    output_size, renderable_objects, rendered_view_layer  # noqa: E402
from logsh_exporter.geometry import as_rendered  # noqa: E402


def roughness_of(exponent):
    """Inverse of `materials.phong_exponent` (the exporter's)."""
    alpha = (1.0 / (2.0 * (exponent + 0.5))) ** 0.5
    return alpha ** 0.5


def cycles_shader(material, entry):
    tree = material.node_tree
    if tree is None:
        material.use_nodes = True
        tree = material.node_tree
    tree.nodes.clear()
    output = tree.nodes.new("ShaderNodeOutputMaterial")

    def diffuse(colour):
        node = tree.nodes.new("ShaderNodeBsdfDiffuse")
        node.inputs["Color"].default_value = (*colour, 1.0)
        node.inputs["Roughness"].default_value = 0.0
        return node

    def glossy(colour, roughness):
        node = tree.nodes.new("ShaderNodeBsdfAnisotropic")  # "Glossy BSDF" in Blender 4+
        node.distribution = "GGX"
        node.inputs["Color"].default_value = (*colour, 1.0)
        node.inputs["Roughness"].default_value = roughness
        return node

    kind = entry["type"]
    if kind in ("diffuse", "heightfield"):
        shader = diffuse(entry["albedo"])
    elif kind == "water":
        shader = glossy(entry["tint"], 0.0)
    else:
        shader = tree.nodes.new("ShaderNodeAddShader")
        tree.links.new(diffuse(entry["albedo"]).outputs[0], shader.inputs[0])
        tree.links.new(glossy(entry["specular"], roughness_of(entry["exponent"])).outputs[0], shader.inputs[1])
    tree.links.new(shader.outputs[0], output.inputs["Surface"])


def main(argv):
    parser = argparse.ArgumentParser(prog="render_cycles.py", description=__doc__.split("\n")[0])
    parser.add_argument("--blend")
    parser.add_argument("--out", required=True)
    parser.add_argument("--frame", type=int)
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--resolution", type=size)
    parser.add_argument("--seed", type=int, default=0, help="Cycles' noise seed (two seeds measure the noise)")
    parser.add_argument("--ladder", type=sample_ladder, help="time renders at these sample counts (1,2,4,...)")
    parser.add_argument("--ladder-denoise", action="store_true",
                        help="with --ladder: also time the counts up to 16 with OpenImageDenoise (prefilter ACCURATE, "
                             "then FAST)")
    parser.add_argument("--as-authored", action="store_true",
                        help="render the .blend's own materials (the truth for the user), not the converted ones")
    parser.add_argument("--bounces", default="0",
                        help="with --as-authored: Cycles' max bounces, or 'default' for the file's light paths (0)")
    parser.add_argument("--denoise", action="store_true", help="OpenImageDenoise the render (albedo and normal)")
    parser.add_argument("--filter", choices=["centre", "box1", "blackman-harris"], default="centre",
                        help="pixel filter: each pixel's centre (as a point-sampled G-buffer), a 1-px box, or 1.5-px "
                             "Blackman-Harris")
    args = parser.parse_args(argv)
    if args.ladder_denoise and not args.ladder:
        sys.exit("error: --ladder-denoise times the ladder's denoised rungs; pass --ladder too")
    if args.ladder_denoise and args.denoise:
        sys.exit("error: --ladder-denoise with --denoise would denoise the plain ladder too; leave out --denoise")
    if args.blend:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend), load_ui=False)
    elif not bpy.data.filepath:
        sys.exit("error: no .blend given; pass --blend FILE")
    scene = bpy.context.scene
    frame = args.frame if args.frame is not None else scene.frame_start
    if args.bounces != "default" and not (args.bounces.isdigit() and int(args.bounces) <= 1024):
        sys.exit(f"error: --bounces {args.bounces}: a count from 0 to 1024, or 'default'")
    name = "authored" if args.as_authored else "cycles"
    if args.bounces != "0":
        name += f"_b{args.bounces}"
    stem = os.path.join(os.path.abspath(args.out), f"{name}.{frame:04d}")
    outputs = [f"{stem}.s{n}.exr" for n in args.ladder] + [stem + ".timing.json"] if args.ladder else \
        [stem + ".exr", stem + ".png"]
    if args.ladder_denoise:
        outputs += [f"{stem}.s{n}.{name}.exr" for name, _ in OIDN_PREFILTERS for n in oidn_counts(args.ladder)]
    for path in outputs:
        if os.path.exists(path):
            sys.exit(f"error: {path} exists; choose another directory")
    os.makedirs(args.out, exist_ok=True)

    water = False
    if not args.as_authored:
        changes = Changes()
        objects, materials_of = as_rendered(scene, rendered_view_layer(scene), renderable_objects, changes)
        options = Options(out=args.out, colour_passes=False, approximate=True)
        table, index_of = material_table(objects, materials_of, find_heightfield(objects, options), changes, options, [])
        for material, index in index_of.items():
            cycles_shader(bpy.data.materials[material], table[index])
        water = any(m["type"] == "water" for m in table.values())

    render, cycles = scene.render, scene.cycles
    render.engine = "CYCLES"
    cycles.device = "CPU"
    cycles.samples = args.samples
    cycles.seed = args.seed
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = args.denoise
    if args.denoise:
        cycles.denoiser = "OPENIMAGEDENOISE"
        cycles.denoising_input_passes = "RGB_ALBEDO_NORMAL"
    cycles.pixel_filter_type, cycles.filter_width = {
        "centre": (DATA_FILTER, DATA_FILTER_WIDTH),
        "box1": ("BOX", 1.0),
        "blackman-harris": ("BLACKMAN_HARRIS", 1.5),
    }[args.filter]
    if args.as_authored or args.bounces != "0":
        if args.bounces != "default":
            cycles.max_bounces = int(args.bounces)
    else:
        cycles.max_bounces = 1 if water else 0
        cycles.glossy_bounces = 1 if water else 0
        cycles.diffuse_bounces = cycles.transmission_bounces = cycles.volume_bounces = 0
        cycles.transparent_max_bounces = 0
        cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
        cycles.blur_glossy = 0.0
        cycles.caustics_reflective = True
    render.use_motion_blur = False
    # The frame and the view layer the exporter takes: the whole frame, one layer.
    render.use_border = False
    layer = rendered_view_layer(scene)
    for other in scene.view_layers:
        other.use = other == layer
    render.use_compositing = render.use_sequencer = False
    render.film_transparent = False
    for attribute in dir(render):  # no metadata (file path, date, host) in the outputs
        if attribute.startswith("use_stamp"):
            setattr(render, attribute, False)
    scene.camera.data.dof.use_dof = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
    if args.resolution:
        render.resolution_x, render.resolution_y = args.resolution
        render.resolution_percentage = 100

    scene.frame_set(frame)
    render.use_file_extension = False
    if args.ladder:
        time_ladder(scene, stem, args.ladder, args.ladder_denoise)
        return
    bpy.ops.render.render()
    save_exr(scene, stem + ".exr")
    settings = render.image_settings
    settings.file_format = "PNG"
    settings.color_depth = "8"
    bpy.data.images["Render Result"].save_render(stem + ".png", scene=scene)
    print(f"wrote {stem}.exr and .png ({args.samples} samples, max bounces {cycles.max_bounces}, "
          f"{'as authored' if args.as_authored else 'converted materials'})")


def sample_ladder(text):
    counts = [int(n) for n in text.split(",")]
    if not counts or any(n < 1 for n in counts):
        raise argparse.ArgumentTypeError(f"{text!r}: sample counts are integers >= 1, comma-separated")
    return counts


# `--ladder-denoise`: the name of each denoised rung's file and its prefilter, and the
# highest sample count denoised (a few samples are where a denoiser is the alternative).
OIDN_PREFILTERS = (("oidn_accurate", "ACCURATE"), ("oidn_fast", "FAST"))
OIDN_MAX_SAMPLES = 16


def oidn_counts(ladder):
    return [n for n in ladder if n <= OIDN_MAX_SAMPLES]


def timed_render(scene, samples):
    scene.cycles.samples = samples
    started = time.perf_counter()
    bpy.ops.render.render()
    return time.perf_counter() - started


def time_ladder(scene, stem, ladder, denoise=False):
    """Renders 1 sample untimed (Cycles loads its kernels), then each count of `ladder`
    timed; with `denoise`, then 1 sample denoised untimed (OpenImageDenoise loads) and
    each count up to `OIDN_MAX_SAMPLES` denoised with each prefilter, timed; writes each
    image and the times."""
    warm_up = timed_render(scene, 1)
    seconds = []
    for count in ladder:
        seconds.append(timed_render(scene, count))
        save_exr(scene, f"{stem}.s{count}.exr")
        print(f"{count} samples: {seconds[-1]:.3f} s")
    timing = {"warm_up_seconds": warm_up, "samples": ladder, "seconds": seconds,
              "threads": scene.render.threads, "resolution": list(output_size(scene))}
    if denoise:
        cycles = scene.cycles
        cycles.use_denoising = True
        cycles.denoiser = "OPENIMAGEDENOISE"
        cycles.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        cycles.denoising_use_gpu = False
        cycles.denoising_prefilter = OIDN_PREFILTERS[0][1]
        timing["oidn_warm_up_seconds"] = timed_render(scene, 1)
        timing["oidn_quality"] = cycles.denoising_quality
        timing["oidn"] = []
        for name, prefilter in OIDN_PREFILTERS:
            cycles.denoising_prefilter = prefilter
            counts, times = oidn_counts(ladder), []
            for count in counts:
                times.append(timed_render(scene, count))
                save_exr(scene, f"{stem}.s{count}.{name}.exr")
                print(f"{count} samples, OpenImageDenoise ({prefilter.lower()} prefilter): {times[-1]:.3f} s")
            timing["oidn"].append({"name": name, "prefilter": prefilter, "samples": counts, "seconds": times})
        cycles.use_denoising = False
    with open(stem + ".timing.json", "w") as f:
        json.dump(timing, f, indent=1)
    print(f"wrote {stem}.timing.json (warm-up render {warm_up:.2f} s)")


def save_exr(scene, path):
    """The last render as linear RGB, half float."""
    result = bpy.data.images["Render Result"]
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):
        settings.media_type = "IMAGE"
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGB"
    settings.color_depth = "16"
    settings.exr_codec = "ZIP"
    result.save_render(path, scene=scene)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
