#!/usr/bin/env bash
# Temporal stability (flicker) of logsh against Cycles at a few samples, plain and with
# OpenImageDenoise, on sequences with a moving light and a static camera: for each scene
# of $SCENES (scripts in blender_scripts/scenes/), the .blend as authored rendered by
# Cycles with Blender's light paths at $TRUTH_SAMPLES samples (render_cycles.py
# --as-authored --bounces default: what the user renders) is the truth; Cycles' ladder
# $LADDER (plain, and up to 16 samples with OpenImageDenoise, prefilter FAST and ACCURATE:
# render_cycles.py --ladder-denoise) and logsh on the export with colour passes are the
# candidates. Prints blender_scripts/flicker.py's table per scene:
#
#     bash blender_scripts/measure_flicker.sh [OUT_DIR]     # default: target/dynamic
#
# In OUT_DIR, per scene: SCENE.blend, SCENE-RESOLUTION-truth/ (the truth),
# SCENE-RESOLUTION-truth-seed1/ (the truth again with --seed 1, the truth's noise floor;
# FLOOR=0 leaves it out), SCENE-ladder/ (Cycles' ladder and its timing JSONs),
# SCENE-auth/ (the export) and SCENE-logsh/ (logsh's render). Each of these but logsh's
# render is made only where absent and kept for later runs (the truths take a minute or
# two, the ladder a quarter of a minute): delete one to make it anew, e.g. after changing
# the .blend, $FRAMES or $RESOLUTION. logsh's render is made anew in every run, after
# `cargo build --release`, and timed as one process over all frames (start-up included).
# Every Cycles render uses the same seed in every frame (Blender's default), as a user's
# sequence does; the ladder's times are on the CPU (Cycles and OpenImageDenoise), so
# nothing else should run on the machine meanwhile.
#
# Needs Blender as a Python module: $LOGSH_BPY_PYTHON, else .venv-bpy/bin/python (made by
# .ci/bpy-setup).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/dynamic}
SCENES=${SCENES:-lantern}
FRAMES=${FRAMES:-"1 2 3"}
RESOLUTION=${RESOLUTION:-240x135}
TRUTH_SAMPLES=${TRUTH_SAMPLES:-512}
LADDER=${LADDER:-1,2,4,8,16}
FLOOR=${FLOOR:-1}
DEVICE=${DEVICE:-cpu}  # logsh render --device
case "$FLOOR" in 0|1) ;; *) echo "error: FLOOR=$FLOOR: 1 or 0" >&2; exit 1 ;; esac
PYTHON=${LOGSH_BPY_PYTHON:-.venv-bpy/bin/python}
"$PYTHON" -c "import bpy" || { echo "error: $PYTHON cannot import bpy (run .ci/bpy-setup)" >&2; exit 1; }
cargo build --release

frames=$(echo $FRAMES | tr ' ' ',')  # 1,2,3: as export_scene.py, logsh render and flicker.py read it
count=$(echo $FRAMES | wc -w)
truth() {  # .blend, directory, render_cycles.py options: each frame of $FRAMES where absent
    local blend=$1 dir=$2
    shift 2
    for frame in $FRAMES; do
        [ -f "$dir/authored_bdefault.$(printf %04d "$frame").exr" ] || "$PYTHON" blender_scripts/render_cycles.py \
            --blend "$blend" --out "$dir" --frame "$frame" --resolution "$RESOLUTION" --samples "$TRUTH_SAMPLES" \
            --as-authored --bounces default "$@"
    done
}

mkdir -p "$OUT"
for scene in $SCENES; do
    blend="$OUT/$scene.blend"
    truth_dir="$OUT/$scene-$RESOLUTION-truth" ladder="$OUT/$scene-ladder"
    export="$OUT/$scene-auth" logsh="$OUT/$scene-logsh"
    [ -f "$blend" ] || "$PYTHON" blender_scripts/scenes/"$scene".py --save "$blend"
    truth "$blend" "$truth_dir"
    floor=()
    if [ "$FLOOR" = 1 ]; then
        truth "$blend" "$OUT/$scene-$RESOLUTION-truth-seed1" --seed 1
        floor=(--second-truth "$OUT/$scene-$RESOLUTION-truth-seed1/authored_bdefault.####.exr")
    fi
    for frame in $FRAMES; do
        [ -f "$ladder/authored_bdefault.$(printf %04d "$frame").timing.json" ] || "$PYTHON" \
            blender_scripts/render_cycles.py --blend "$blend" --out "$ladder" --frame "$frame" \
            --resolution "$RESOLUTION" --as-authored --bounces default --ladder "$LADDER" --ladder-denoise
    done
    if [ ! -f "$export/scene.json" ]; then
        rm -rf "$export"
        "$PYTHON" blender_scripts/export_scene.py --blend "$blend" --out "$export" --frames "$frames" \
            --resolution "$RESOLUTION"
    fi
    rm -rf "$logsh"
    started=$(date +%s.%N)
    target/release/logsh render "$export" --frames "$frames" --out "$logsh" --device "$DEVICE" --progress none
    seconds=$(echo "$started $(date +%s.%N) $count" | awk '{ printf "%.3f", ($2 - $1) / $3 }')

    candidates=("logsh=$logsh/render.####.exr")
    rungs=$(echo "$LADDER" | tr ',' ' ')
    for n in $rungs; do
        candidates+=("cycles $n=$ladder/authored_bdefault.####.s$n.exr")
        if [ "$n" -le 16 ]; then  # render_cycles.py's OIDN_MAX_SAMPLES
            candidates+=("cycles $n + OIDN fast=$ladder/authored_bdefault.####.s$n.oidn_fast.exr"
                "cycles $n + OIDN accurate=$ladder/authored_bdefault.####.s$n.oidn_accurate.exr")
        fi
    done
    echo
    echo "## $scene, frames $frames, $RESOLUTION (truth: $TRUTH_SAMPLES samples)"
    "$PYTHON" blender_scripts/flicker.py --truth "$truth_dir/authored_bdefault.####.exr" --frames "$frames" \
        --mask "$logsh/render.####.exr" --timing "$ladder/authored_bdefault.####.timing.json" \
        --seconds "logsh=$seconds" "${floor[@]}" "${candidates[@]}"
done
