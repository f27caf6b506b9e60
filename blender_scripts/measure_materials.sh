#!/usr/bin/env bash
# logsh against the user's truth for materials: Cycles rendering each .blend as authored
# with direct light only (render_cycles.py --as-authored --bounces 0), on scenes built
# here, exported with their colour passes (the exporter's default); prints
# examples/cycles_compare.rs's table (docs/method/materials.md,
# its "default, --bounces 0" rows: the truth has no bounce light):
#
#     bash blender_scripts/measure_materials.sh [OUT_DIR]     # default: target/materials
#
# $SCENES are scripts of blender_scripts/scenes/, exported and rendered at $RESOLUTION,
# frame 1, the truth with $TRUTH_SAMPLES samples (kept in OUT_DIR and reused by later
# runs, as each takes minutes; the export is made anew, with $EXPORT_OPTIONS). Needs Blender as a Python module: $LOGSH_BPY_PYTHON,
# else .venv-bpy/bin/python (made by .ci/bpy-setup).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/materials}
SCENES=${SCENES:-"textured primitives glossy sun_lamp cones principled_tiles primitives_sun_lamp primitives_hdri_sun"}
RESOLUTION=${RESOLUTION:-240x135}
TRUTH_SAMPLES=${TRUTH_SAMPLES:-1024}
EXPORT_OPTIONS=${EXPORT_OPTIONS:-}
PYTHON=${LOGSH_BPY_PYTHON:-.venv-bpy/bin/python}
"$PYTHON" -c "import bpy" || { echo "error: $PYTHON cannot import bpy (run .ci/bpy-setup)" >&2; exit 1; }
cargo build --release --example cycles_compare

mkdir -p "$OUT"
dirs=()
for scene in $SCENES; do
    [ -f "$OUT/$scene.blend" ] || "$PYTHON" blender_scripts/scenes/"$scene".py --save "$OUT/$scene.blend"
    dir="$OUT/$scene-$RESOLUTION" truth="$OUT/$scene-$RESOLUTION-truth"
    if [ ! -f "$truth/authored.0001.exr" ]; then
        rm -rf "$truth"
        "$PYTHON" blender_scripts/render_cycles.py --blend "$OUT/$scene.blend" --out "$truth" --frame 1 \
            --resolution "$RESOLUTION" --as-authored --bounces 0 --samples "$TRUTH_SAMPLES"
    fi
    # Exported anew each run (seconds), so that the table follows the exporter.
    rm -rf "$dir"
    "$PYTHON" blender_scripts/export_scene.py --blend "$OUT/$scene.blend" --out "$dir" \
        --frames 1 --resolution "$RESOLUTION" $EXPORT_OPTIONS
    cp "$truth/authored.0001.exr" "$dir/"
    dirs+=("$dir")
done
target/release/examples/cycles_compare --quick "${dirs[@]}"
