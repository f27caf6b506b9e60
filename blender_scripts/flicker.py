"""Measures the temporal stability (flicker) of rendered sequences against a truth sequence:
for each candidate, the part of its change from frame to frame that is not the truth's
change, and its plain error per frame for context. Prints a markdown table.

    python blender_scripts/flicker.py --truth T.####.exr --frames 1-3 [--mask M.####.exr]
        [--timing J.####.timing.json] [--seconds LABEL=S ...] [--second-truth T2.####.exr]
        [LABEL=]C.####.exr ...

Paths are templates: a run of `#` is the frame number, zero-padded to the run's length
(`render.####.exr`: `render.0001.exr`). `--frames` takes `1-3`, `1..3` or `1,2,5`; the
frames need not be consecutive, but each pair of neighbours in the list is one pair.
Every file is read with `logsh_exporter/exr.py` (scan-line EXR, no, ZIPS or ZIP
compression) as its `R`, `G`, `B` channels, the beauty of a logsh render or a Cycles
render from `render_cycles.py`. A candidate is labelled by its template, or by `LABEL=`.

The measures, each a mean over the pixels that are not background and over R, G and B:

- flicker: `|(C[f+1] - C[f]) - (T[f+1] - T[f])|`, averaged over the pairs of frames: the
  change from one frame to the next that the truth does not have (noise that differs
  from frame to frame, a shading error that moves with the light). A candidate that is
  wrong by the same amount in every frame does not flicker;
- error: `|C[f] - T[f]|` for each frame, and their mean;
- for scale, the truth's own change `|T[f+1] - T[f]|` per pair and the truth's mean
  value (printed above the table), and each candidate's flicker as a fraction of that
  change.

Background: a pixel counts where `--mask`'s alpha (`A`, e.g. the logsh beauty, whose alpha
is above 0.5 on geometry) is above 0.5; without `--mask`, where the truth's alpha is,
if the truth has an `A` channel; else every pixel counts (a warning says so). A pair of
frames counts the pixels that are not background in both.

The truth's own noise (a Cycles render at a finite sample count) adds to every
candidate's flicker and error. `--second-truth` estimates it: the same truth rendered with
another seed (`render_cycles.py --seed 1`). The two differ by two independent noises, so
their flicker and error (the row `truth, second seed`), divided by sqrt(2), are those of
a perfect candidate against the truth: the row `floor (est.)`. The column `flicker - floor` removes the floor in quadrature,
sqrt(flicker^2 - floor^2), right where the candidate's and the truth's noise are
independent and alike in shape (an estimate, not a subtraction that holds pixel by
pixel).

`--timing` reads `render_cycles.py --ladder`'s `DIR/NAME.NNNN.timing.json` for each
frame and gives each candidate whose file it names (`NAME.NNNN.sK.exr`,
`NAME.NNNN.sK.oidn_fast.exr`, ...) its seconds per frame, the mean over the frames;
`--seconds LABEL=S` gives the candidate labelled LABEL S seconds per frame (a logsh
render's time, say).
"""
import argparse
import json
import math
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from logsh_exporter.exr import read_exr_channels  # noqa: E402

RGB = ["R", "G", "B"]


def frame_list(text):
    frames = []
    for part in text.split(","):
        match = re.fullmatch(r"\s*(-?\d+)\s*(?:(?:-|\.\.)\s*(-?\d+)\s*)?", part)
        if not match:
            raise argparse.ArgumentTypeError(f"{part!r} is not a frame spec like 1-3, 1..3 or 1,2,5")
        first = int(match.group(1))
        last = int(match.group(2)) if match.group(2) is not None else first
        if last < first:
            raise argparse.ArgumentTypeError(f"{part!r}: the range is empty")
        frames.extend(range(first, last + 1))
    if len(frames) < 2:
        raise argparse.ArgumentTypeError(f"{text!r}: flicker needs two frames at least")
    return frames


def template(text):
    if "#" not in text:
        raise argparse.ArgumentTypeError(f"{text!r} has no run of # for the frame number")
    return text


def candidate(text):
    label, _, path = text.rpartition("=")
    return (label or path), template(path)


def labelled_seconds(text):
    label, _, value = text.rpartition("=")
    try:
        return label, float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not LABEL=SECONDS") from None


def at_frame(path_template, frame):
    return re.sub(r"#+", lambda run: f"{frame:0{len(run.group(0))}d}", path_template)


def existing_at_frame(path_template, frame):
    """`at_frame`, which must exist: the script stops, naming it, where it does not."""
    path = at_frame(path_template, frame)
    if not os.path.isfile(path):
        sys.exit(f"error: {path} does not exist")
    return path


def read_rgb(path):
    channels = read_exr_channels(path, RGB)
    return np.stack([channels[c] for c in RGB], axis=-1).astype(np.float64)


def read_alpha(path):
    """The `A` channel, or None where the file has none."""
    try:
        return read_exr_channels(path, ["A"])["A"]
    except ValueError as error:
        if "no channel" in str(error):
            return None
        raise


def sequence(path_template, frames):
    images = {}
    for frame in frames:
        images[frame] = read_rgb(existing_at_frame(path_template, frame))
    return images


def masks(args, truth_template):
    """Per frame, the pixels that are not background (bool, H x W)."""
    source = args.mask or truth_template
    out = {}
    for frame in args.frames:
        alpha = read_alpha(at_frame(source, frame))
        if alpha is None:
            if args.mask:
                sys.exit(f"error: {at_frame(source, frame)} has no A channel to mask with")
            out = None
            break
        out[frame] = alpha > 0.5
    if out is None:
        print("warning: no --mask and the truth has no alpha: every pixel counts, background included",
              file=sys.stderr)
    return out


def mean_over(values, mask):
    """Mean of |values| (H x W x 3) over the masked pixels and RGB."""
    values = np.abs(values)
    return float(values.mean() if mask is None else values[mask].mean())


def pairs(frames):
    return list(zip(frames[:-1], frames[1:]))


def measure(images, truth, frames, mask):
    """(flicker per pair, error per frame) of `images` against `truth`."""
    def mask_of(*fs):
        return None if mask is None else np.logical_and.reduce([mask[f] for f in fs])
    flicker = [mean_over((images[b] - images[a]) - (truth[b] - truth[a]), mask_of(a, b)) for a, b in pairs(frames)]
    error = [mean_over(images[f] - truth[f], mask_of(f)) for f in frames]
    return flicker, error


def ladder_seconds(timing_template, frames):
    """{file name with #### for the frame: mean seconds per frame} from the ladder's JSONs."""
    per_file = {}
    for frame in frames:
        path = existing_at_frame(timing_template, frame)
        with open(path) as f:
            timing = json.load(f)
        stem = os.path.basename(path)[:-len(".timing.json")]
        generic = re.sub(r"\.\d+$", ".####", stem)
        rungs = [(f"{generic}.s{n}.exr", s) for n, s in zip(timing["samples"], timing["seconds"])]
        for denoised in timing.get("oidn", []):
            rungs += [(f"{generic}.s{n}.{denoised['name']}.exr", s)
                      for n, s in zip(denoised["samples"], denoised["seconds"])]
        for name, seconds in rungs:
            per_file.setdefault(name, []).append(seconds)
    return {name: sum(times) / len(times) for name, times in per_file.items() if len(times) == len(frames)}


def main(argv):
    parser = argparse.ArgumentParser(prog="flicker.py", description=__doc__.split("\n")[0])
    parser.add_argument("--truth", type=template, required=True, help="the truth sequence (template with ####)")
    parser.add_argument("--frames", type=frame_list, required=True, help="frames: 1-3, 1..3 or 1,2,5")
    parser.add_argument("--mask", type=template,
                        help="a sequence whose alpha > 0.5 marks the pixels that count (e.g. logsh's beauty)")
    parser.add_argument("--timing", type=template, help="render_cycles.py --ladder's timing JSON (template)")
    parser.add_argument("--seconds", type=labelled_seconds, action="append", default=[],
                        help="LABEL=S: S seconds per frame for the candidate labelled LABEL")
    parser.add_argument("--second-truth", type=template,
                        help="the truth rendered with another seed: estimates the truth's noise floor")
    parser.add_argument("candidates", nargs="+", type=candidate, help="[LABEL=]TEMPLATE of each candidate")
    args = parser.parse_args(argv)
    frames = args.frames

    truth = sequence(args.truth, frames)
    mask = masks(args, args.truth)
    shape = truth[frames[0]].shape
    change = [mean_over(truth[b] - truth[a], None if mask is None else mask[a] & mask[b]) for a, b in pairs(frames)]
    counted = shape[0] * shape[1] if mask is None else int(np.mean([mask[f].sum() for f in frames]))
    seconds = ladder_seconds(args.timing, frames) if args.timing else {}
    given = dict(args.seconds)
    unknown = set(given) - {label for label, _ in args.candidates}
    if unknown:
        sys.exit(f"error: --seconds names {sorted(unknown)[0]!r}, which labels no candidate")

    rows = []
    floor = None
    if args.second_truth:
        second = sequence(args.second_truth, frames)
        flicker, error = measure(second, truth, frames, mask)
        rows.append(("truth, second seed", None, flicker, error))
        floor = (np.mean(flicker) / math.sqrt(2.0), np.mean(error) / math.sqrt(2.0))
    for label, path_template in args.candidates:
        images = sequence(path_template, frames)
        for frame in frames:
            if images[frame].shape != shape:
                sys.exit(f"error: {at_frame(path_template, frame)} is {images[frame].shape[1]}x"
                         f"{images[frame].shape[0]}, the truth {shape[1]}x{shape[0]}")
        flicker, error = measure(images, truth, frames, mask)
        rows.append((label, given.get(label, seconds.get(os.path.basename(path_template))), flicker, error))

    scale = np.mean(change)
    level = np.mean([mean_over(truth[f], None if mask is None else mask[f]) for f in frames])
    print(f"truth {args.truth}, frames {','.join(map(str, frames))}: {counted} of {shape[1]}x{shape[0]} pixels "
          f"counted per frame; the truth's own change |T[f+1]-T[f]| per pair: "
          + ", ".join(f"{c:.5f}" for c in change) + f" (mean {scale:.5f}); the truth's mean value {level:.5f}")
    if floor:
        print(f"noise floor of the truth (second seed / sqrt 2): flicker {floor[0]:.5f}, error {floor[1]:.5f}")
    pair_names = [f"{a}→{b}" for a, b in pairs(frames)]
    header = ["candidate", "s/frame", "flicker", "flicker / truth change"]
    if floor:
        header.append("flicker - floor")
    header += [f"flicker {p}" for p in pair_names] + [f"error f{f}" for f in frames] + ["mean error"]
    print()
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join(["---"] + ["---:"] * (len(header) - 1)) + "|")
    if floor:
        cells = ["floor (est.)", "", f"{floor[0]:.5f}", f"{floor[0] / scale:.3f}", ""] + [""] * len(pair_names) \
            + [""] * len(frames) + [f"{floor[1]:.5f}"]
        print("| " + " | ".join(cells) + " |")
    for label, time, flicker, error in rows:
        mean_flicker = float(np.mean(flicker))
        cells = [label, "" if time is None else f"{time:.3f}", f"{mean_flicker:.5f}", f"{mean_flicker / scale:.3f}"]
        if floor:
            cells.append(f"{math.sqrt(max(0.0, mean_flicker ** 2 - floor[0] ** 2)):.5f}")
        cells += [f"{v:.5f}" for v in flicker] + [f"{v:.5f}" for v in error] + [f"{np.mean(error):.5f}"]
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
