#!/usr/bin/env bash
# logsh against Cycles in time at equal error, on the same .blend, in one run
# (examples/cycles_timing.rs; the "Against Cycles in time" table of docs/accuracy.md):
#
#     bash blender_scripts/time_against_cycles.sh [OUT_DIR]     # default: target/cycles-timing
#
# For each scene of $SCENES (scripts in blender_scripts/scenes/) at each size of
# $RESOLUTIONS: builds the .blend, exports frame 1, renders converged Cycles
# ($TRUTH_SAMPLES samples; kept in OUT_DIR and reused by later runs, as it takes minutes),
# then, in this run, times Cycles warm over the ladder $LADDER and logsh's presets as
# whole processes, and prints the table. Nothing else should run on the machine meanwhile.
# With LADDER_DENOISE=1 (the default; 0 leaves it out) the ladder's counts up to 16 are
# also timed with OpenImageDenoise, prefilter ACCURATE and FAST (render_cycles.py
# --ladder-denoise), and the table names the cheapest Cycles rung, plain or denoised,
# whose error is at most each logsh preset's.
#
# Needs Blender as a Python module: $LOGSH_BPY_PYTHON, else .venv-bpy/bin/python (made by
# .ci/bpy-setup), else python3.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/cycles-timing}
SCENES=${SCENES:-"cones primitives"}
RESOLUTIONS=${RESOLUTIONS:-"480x270 960x540"}
LADDER=${LADDER:-1,2,4,8,16,32,64}
TRUTH_SAMPLES=${TRUTH_SAMPLES:-1024}
LADDER_DENOISE=${LADDER_DENOISE:-1}
# Cycles' light paths, for the truth and the ladder alike: "default" (the .blend's own,
# bounce light included, what logsh's default preset shades) or a max bounce count; 0
# is direct light only, logsh's method alone (its presets then shade --bounces 0 too).
BOUNCES=${BOUNCES:-default}
if [ "$BOUNCES" = 0 ]; then stem=cycles; light_paths=(); else stem=cycles_b$BOUNCES; light_paths=(--bounces "$BOUNCES"); fi
ladder_options=()
case "$LADDER_DENOISE" in
    1) ladder_options=(--ladder-denoise) ;;
    0) ;;
    *) echo "error: LADDER_DENOISE=$LADDER_DENOISE: 1 or 0" >&2; exit 1 ;;
esac
PYTHON=${LOGSH_BPY_PYTHON:-}
if [ -z "$PYTHON" ]; then
    if [ -x .venv-bpy/bin/python ]; then PYTHON=.venv-bpy/bin/python; else PYTHON=python3; fi
fi
"$PYTHON" -c "import bpy" || { echo "error: $PYTHON cannot import bpy (run .ci/bpy-setup)" >&2; exit 1; }
cargo build --release --example cycles_timing
cargo build --release

mkdir -p "$OUT"
dirs=()
for scene in $SCENES; do
    [ -f "$OUT/$scene.blend" ] || "$PYTHON" blender_scripts/scenes/"$scene".py --save "$OUT/$scene.blend"
    for resolution in $RESOLUTIONS; do
        dir="$OUT/$scene-$resolution"
        if [ ! -f "$dir/$stem.0001.exr" ]; then
            rm -rf "$dir"
            # Without colour passes: the truth below is render_cycles.py's converted materials.
            "$PYTHON" blender_scripts/export_scene.py --blend "$OUT/$scene.blend" --out "$dir" \
                --frames 1 --resolution "$resolution" --no-colour-passes
            "$PYTHON" blender_scripts/render_cycles.py --blend "$OUT/$scene.blend" --out "$dir" \
                --samples "$TRUTH_SAMPLES" --resolution "$resolution" "${light_paths[@]}"
        fi
        # The ladder is timed afresh in every run (these files are this script's products).
        rm -f "$dir"/$stem.0001.s*.exr "$dir/$stem.0001.timing.json"
        "$PYTHON" blender_scripts/render_cycles.py --blend "$OUT/$scene.blend" --out "$dir" \
            --ladder "$LADDER" "${ladder_options[@]}" --resolution "$resolution" "${light_paths[@]}"
        dirs+=("$dir")
    done
done
./target/release/examples/cycles_timing --truth "$stem" "${dirs[@]}"
