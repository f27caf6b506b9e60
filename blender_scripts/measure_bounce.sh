#!/usr/bin/env bash
# logsh against the truths for bounce light, on scenes built here, frame 1: Cycles with
# Blender's own light paths on the exporter's converted materials (render_cycles.py
# --bounces default; the export without colour passes), the bounce apart from the
# materials; and on the .blend as authored (--as-authored --bounces default; the export
# with its colour passes), what the user renders. Prints examples/cycles_compare.rs's
# table (docs/method/bounce-light.md):
#
#     bash blender_scripts/measure_bounce.sh [OUT_DIR]     # default: target/bounce
#
# $SCENES are scripts of blender_scripts/scenes/; $CONVERTED those also measured on
# converted materials. Truths take $TRUTH_SAMPLES samples at $RESOLUTION and are kept in
# OUT_DIR for later runs (each takes a minute or two); the exports are made anew.
# Needs Blender as a Python module: $LOGSH_BPY_PYTHON, else .venv-bpy/bin/python (made by
# .ci/bpy-setup).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/bounce}
SCENES=${SCENES:-"primitives sun_lamp canyon cones glossy textured dunes primitives_hdri_sun primitives_sun_lamp"}
CONVERTED=${CONVERTED:-"primitives sun_lamp canyon cones"}
RESOLUTION=${RESOLUTION:-240x135}
TRUTH_SAMPLES=${TRUTH_SAMPLES:-1024}
PYTHON=${LOGSH_BPY_PYTHON:-.venv-bpy/bin/python}
"$PYTHON" -c "import bpy" || { echo "error: $PYTHON cannot import bpy (run .ci/bpy-setup)" >&2; exit 1; }
cargo build --release --example cycles_compare

mkdir -p "$OUT"
truth() {  # scene, file stem, render_cycles.py options
    local scene=$1 stem=$2 dir="$OUT/$1-$RESOLUTION-truth"
    shift 2
    [ -f "$dir/$stem.0001.exr" ] || "$PYTHON" blender_scripts/render_cycles.py --blend "$OUT/$scene.blend" \
        --out "$dir" --frame 1 --resolution "$RESOLUTION" --samples "$TRUTH_SAMPLES" "$@"
}
export_to() {  # scene, directory, exporter options
    local scene=$1 dir=$2
    shift 2
    rm -rf "$dir"
    "$PYTHON" blender_scripts/export_scene.py --blend "$OUT/$scene.blend" --out "$dir" --frames 1 \
        --resolution "$RESOLUTION" "$@"
}
dirs=()
for scene in $SCENES; do
    [ -f "$OUT/$scene.blend" ] || "$PYTHON" blender_scripts/scenes/"$scene".py --save "$OUT/$scene.blend"
    truth "$scene" authored_bdefault --as-authored --bounces default
    export_to "$scene" "$OUT/$scene-$RESOLUTION"
    cp "$OUT/$scene-$RESOLUTION-truth/authored_bdefault.0001.exr" "$OUT/$scene-$RESOLUTION/"
    dirs+=("$OUT/$scene-$RESOLUTION")
    if [[ " $CONVERTED " == *" $scene "* ]]; then
        truth "$scene" cycles_bdefault --bounces default
        truth "$scene" cycles
        export_to "$scene" "$OUT/$scene-$RESOLUTION-converted" --no-colour-passes
        cp "$OUT/$scene-$RESOLUTION-truth/"{cycles,cycles_bdefault}.0001.exr "$OUT/$scene-$RESOLUTION-converted/"
        dirs+=("$OUT/$scene-$RESOLUTION-converted")
    fi
done
target/release/examples/cycles_compare --quick "${dirs[@]}"
