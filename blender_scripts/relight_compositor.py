"""Builds logsh's diffuse relight in Blender's compositor from a frame's transfer layers
(`logsh render --transfer`), with the environment's turn and strength as two Value nodes
a compositor can drive (docs/compositing.md).

    python blender_scripts/relight_compositor.py FRAME.exr LIGHT.json [--rotation DEG]
        [--strength S] [--write OUT.exr] [--save OUT.blend]
    blender -b -P blender_scripts/relight_compositor.py -- FRAME.exr LIGHT.json ...

`python` is one with Blender's `bpy` module (`pip install bpy`), or run it in Blender as
the second line does. LIGHT.json is what `logsh relight` writes beside each frame
(`<frame>.light.json`: the light's SH vector, RGB per coefficient). The node tree
computes, per colour channel,

    diffuse = albedo * max(strength * sum_k sh_diffuse_k L'_k, 0) + lamps_diffuse

with `L'` the light turned by `rotation` degrees about Z from where the frame was
rendered: band by band the `(m, -m)` pair turns by `m` times the angle (`rotate_z` in
src/sh/rotation.rs), which the tree does with cosine and sine nodes, so the turn stays
live. A LIGHT.json from a relight that turned the light (`--light-rotation`) is turned
back first, by the turn it records (`turned_from_frame`), so `--rotation 40` means what
`logsh relight --light-rotation 40` means whichever relight wrote it. The
frame's Sun lamps stay in `lamps_diffuse` as rendered (`logsh relight` turns them), and
the script says so. With `--write`, the composite is rendered to OUT.exr (linear,
float; the name must end in `.exr` and is written as given); with `--save`, the .blend
is kept. The glossy term reads a prefiltered map along
each pixel's mirror direction, which a compositor cannot: take it from `logsh relight`.
"""
import argparse
import json
import os
import sys


def arguments():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("frame", help="a frame rendered with logsh render --transfer")
    parser.add_argument("light", help="the light's SH vector, <frame>.light.json from logsh relight")
    parser.add_argument("--rotation", type=float, default=0.0, help="degrees about Z (the Value node's start)")
    parser.add_argument("--strength", type=float, default=1.0, help="the environment's strength (the Value node's start)")
    parser.add_argument("--write", help="render the composite to this EXR")
    parser.add_argument("--save", help="save the .blend with the node tree")
    return parser.parse_args(argv)


def exr_header(path):
    """Width and height of an EXR's data window and its `logshTransfer` header (a dict),
    from the first part's header."""
    import struct

    size, transfer = None, None
    damaged = f"{path}: the file ends early or its header is damaged; write or copy it again"

    def exactly(f, count):
        data = f.read(count)
        if len(data) != count:
            fail(damaged)
        return data

    def text(f):
        """A null-terminated name (attribute names and types are at most 255 bytes)."""
        name = bytearray()
        while (byte := exactly(f, 1)) != b"\x00":
            name += byte
            if len(name) > 255:
                fail(damaged)
        return bytes(name)

    with open(path, "rb") as f:
        if f.read(4) != b"\x76\x2f\x31\x01":
            fail(f"{path}: not an EXR file")
        exactly(f, 4)
        while name := text(f):
            text(f)
            (length,) = struct.unpack("<i", exactly(f, 4))
            if length < 0:
                fail(damaged)
            value = exactly(f, length)
            try:
                if name == b"dataWindow":
                    x0, y0, x1, y1 = struct.unpack("<4i", value)
                    size = (x1 - x0 + 1, y1 - y0 + 1)
                elif name == b"logshTransfer":
                    transfer = json.loads(value.decode("utf-8"))
            except (struct.error, ValueError):
                fail(f"{path}: its {name.decode('latin-1')} header does not read")
    if size is None:
        fail(f"{path}: no dataWindow in its header")
    if transfer is None:
        fail(f"{path}: no logshTransfer header: render the frame with logsh render --transfer")
    return size, transfer


def rotate_z(sh, order, degrees):
    """The RGB SH vector `sh` turned `degrees` about Z (src/sh/rotation.rs's rotate_z)."""
    import math

    out = [list(c) for c in sh]
    for l in range(1, order):
        for m in range(1, l + 1):
            c, s = math.cos(m * math.radians(degrees)), math.sin(m * math.radians(degrees))
            plus, minus = l * l + l + m, l * l + l - m
            for k in range(3):
                a, b = out[plus][k], out[minus][k]
                out[plus][k], out[minus][k] = a * c - b * s, a * s + b * c
    return out


def from_frame(light, transfer, light_path, frame_path):
    """`light` turned back to where the frame was rendered: the turn of its map beyond
    the render's, which `logsh relight --light-rotation` gave it (an environment's
    `source` records its turn; a constant light has none to undo)."""
    order = transfer["sh"]["order"]
    if light["order"] != order:
        fail(f"{light_path} is a light of order {light['order']} but {frame_path} was rendered at order {order}: "
             "take the light.json of a relight of this frame")
    beyond = light.get("turned_from_frame")
    if not isinstance(beyond, (int, float)):
        # A light.json of an earlier logsh: an environment's source records its turn.
        source = light.get("source", {})
        turn = source.get("environment", {}).get("turn") if isinstance(source, dict) else None
        rendered = transfer.get("light_turn", transfer["light"].get("environment", {}).get("turn", 0.0))
        beyond = (turn - rendered) if turn is not None else 0.0
        if isinstance(source, dict) and "sh" in source:
            fail(f"{light_path}: a light.json of an earlier logsh, which does not record how far it turned an sh "
                 "light: relight the frame again with this logsh")
    if beyond != 0.0:
        print(f"note: {light_path} is the light turned {beyond:g} deg from the frame's "
              f"(logsh relight --light-rotation); turned back, so --rotation starts from the frame's light")
        light = dict(light, sh=rotate_z(light["sh"], order, -beyond))
    if transfer.get("sun_lamps"):
        count = len(transfer["sun_lamps"])
        print(f"note: {frame_path} has {count} Sun lamp{'s' if count > 1 else ''}, which stay as rendered in "
              "lamps_diffuse here (logsh relight --light-rotation turns them)")
    return light


def fail(message):
    print(f"error: {message}", file=sys.stderr)
    sys.exit(1)


class Tree:
    """A compositor node tree with arithmetic on sockets."""

    def __init__(self, tree):
        self.tree = tree
        self.column = 0

    def node(self, kind, **settings):
        node = self.tree.nodes.new(kind)
        for key, value in settings.items():
            setattr(node, key, value)
        self.column += 1
        node.location = (200 * (self.column // 40), -60 * (self.column % 40))
        return node

    def link(self, output, node_input):
        self.tree.links.new(output, node_input)

    def math(self, operation, a, b=None):
        node = self.node("ShaderNodeMath", operation=operation)
        for socket, value in ((node.inputs[0], a), (node.inputs[1], b)):
            if value is None:
                continue
            if isinstance(value, (int, float)):
                socket.default_value = float(value)
            else:
                self.link(value, socket)
        return node.outputs[0]

    def total(self, sockets):
        """The sum of `sockets` as a balanced tree of Add nodes."""
        while len(sockets) > 1:
            sockets = [self.math("ADD", sockets[i], sockets[i + 1]) if i + 1 < len(sockets) else sockets[i]
                       for i in range(0, len(sockets), 2)]
        return sockets[0]

    def channels(self, output):
        separate = self.node("CompositorNodeSeparateColor")
        self.link(output, separate.inputs[0])
        return [separate.outputs[k] for k in range(4)]


def build(scene, image, light, rotation, strength):
    import bpy

    tree = bpy.data.node_groups.new("logsh diffuse relight", "CompositorNodeTree")
    scene.compositing_node_group = tree
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    t = Tree(tree)
    source = t.node("CompositorNodeImage", image=image)
    order = light["order"]
    count = order * order
    names = {o.name for o in source.outputs}
    for layer in [f"sh_diffuse_{b}" for b in range(0, count, 4)] + ["albedo", "lamps_diffuse"]:
        if layer not in names:
            fail(f"{image.filepath}: no {layer} pass (render it with logsh render --transfer at order {order})")
    coefficients = []
    for block in range(0, count, 4):
        coefficients += t.channels(source.outputs[f"sh_diffuse_{block}"])[: min(4, count - block)]
    turn = t.node("ShaderNodeValue", label="environment rotation (degrees)")
    turn.outputs[0].default_value = rotation
    scale = t.node("ShaderNodeValue", label="environment strength")
    scale.outputs[0].default_value = strength
    radians = t.math("RADIANS", turn.outputs[0])
    phases = [(t.math("COSINE", t.math("MULTIPLY", radians, m)), t.math("SINE", t.math("MULTIPLY", radians, m)))
              for m in range(order)]
    sh = light["sh"]
    albedo = t.channels(source.outputs["albedo"])
    lamps = t.channels(source.outputs["lamps_diffuse"])
    combine = t.node("CompositorNodeCombineColor")
    for c in range(3):
        terms = [t.math("MULTIPLY", coefficients[l * l + l], sh[l * l + l][c]) for l in range(order)]
        for m in range(1, order):
            # T . rotate_z(L) over the (l, m), (l, -m) pairs of every band l >= m:
            # cos(m a) sum (a T_m + b T_-m) + sin(m a) sum (a T_-m - b T_m).
            along, across = [], []
            for l in range(m, order):
                plus, minus = l * l + l + m, l * l + l - m
                a, b = sh[plus][c], sh[minus][c]
                along += [t.math("MULTIPLY", coefficients[plus], a), t.math("MULTIPLY", coefficients[minus], b)]
                across += [t.math("MULTIPLY", coefficients[minus], a), t.math("MULTIPLY", coefficients[plus], -b)]
            terms.append(t.math("MULTIPLY", t.total(along), phases[m][0]))
            terms.append(t.math("MULTIPLY", t.total(across), phases[m][1]))
        lit = t.math("MAXIMUM", t.math("MULTIPLY", t.total(terms), scale.outputs[0]), 0.0)
        t.link(t.math("ADD", t.math("MULTIPLY", lit, albedo[c]), lamps[c]), combine.inputs[c])
    t.link(source.outputs["Alpha"], combine.inputs[3])
    output = t.node("NodeGroupOutput")
    t.link(combine.outputs[0], output.inputs[0])


def main():
    import bpy

    args = arguments()
    for path in (args.frame, args.light):
        if not os.path.isfile(path):
            fail(f"{path}: no such file")
    with open(args.light) as f:
        light = json.load(f)
    if not isinstance(light.get("order"), int) or len(light.get("sh", [])) != light["order"] ** 2:
        fail(f"{args.light}: not a light written by logsh relight (an order and order^2 RGB coefficients)")
    # The composite is written to --write as named (no extension added, no '#' replaced
    # by the frame number), so that the check below is of the file written.
    if args.write and not args.write.lower().endswith(".exr"):
        fail(f"--write {args.write}: give an .exr file name")
    if args.write and "#" in args.write:
        fail(f"--write {args.write}: Blender would write a frame number in place of its '#'; give a name without")
    inputs = (os.path.realpath(args.frame), os.path.realpath(args.light))
    for output in (args.write, args.save):
        same = output and os.path.exists(output) and any(os.path.samefile(output, i) for i in inputs)
        if output and (os.path.realpath(output) in inputs or same):
            fail(f"{output}: would be written over an input")
    if args.save and not args.save.lower().endswith(".blend"):
        fail(f"--save {args.save}: give a .blend file name")
    if args.write and args.save and os.path.realpath(args.write) == os.path.realpath(args.save):
        fail(f"{args.write}: --write and --save name the same file")
    size, transfer = exr_header(args.frame)
    light = from_frame(light, transfer, args.light, args.frame)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    image = bpy.data.images.load(os.path.abspath(args.frame))
    build(scene, image, light, args.rotation, args.strength)
    # The composite has the scene's resolution: the frame's.
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    if args.write:
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.use_file_extension = False
        scene.render.filepath = os.path.abspath(args.write)
        bpy.ops.render.render(write_still=True)
        print(f"wrote {args.write}")
    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.save))
        print(f"saved {args.save}")


if __name__ == "__main__":
    main()
