#!/usr/bin/env bash
# The render engine's cost against exporting once and running `logsh render` by hand: a
# 24-frame 480x270 sequence of `cones`, both ways, alternated, in one run.
#
#     bash blender_scripts/measure_engine.sh [ROUNDS]
#
# Needs .venv-bpy (.ci/bpy-setup) and a release build (cargo build --release). Prints the
# seconds of each way per round and their ratio (engine / by hand).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${LOGSH_BPY_PYTHON:-$PWD/.venv-bpy/bin/python}
LOGSH=$PWD/target/release/logsh
ROUNDS=${1:-2}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
"$PY" blender_scripts/scenes/cones.py --save "$WORK/cones.blend" >/dev/null
"$PY" - "$WORK/cones.blend" <<'PY' >/dev/null
import sys, bpy
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
scene = bpy.context.scene
scene.frame_start, scene.frame_end = 1, 24
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 480, 270, 100
bpy.ops.wm.save_mainfile()
PY

by_hand() {
    rm -rf "$WORK/export" "$WORK/shaded"
    "$PY" blender_scripts/export_scene.py --blend "$WORK/cones.blend" --out "$WORK/export" >/dev/null
    "$LOGSH" render "$WORK/export" --out "$WORK/shaded" --progress none --colour-type float >/dev/null
}

engine() {
    rm -rf "$WORK/frames"
    LOGSH_BINARY=$LOGSH "$PY" - "$WORK/cones.blend" "$WORK/frames/frame.####" <<'PY' >/dev/null
import os, sys
sys.path.insert(0, os.path.join(os.getcwd(), "blender_scripts"))
import bpy
import logsh_exporter
logsh_exporter.register()
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
scene = bpy.context.scene
scene.render.engine = "LOGSH"
settings = scene.render.image_settings
if hasattr(settings, "media_type"):
    settings.media_type = "MULTI_LAYER_IMAGE"
settings.file_format = "OPEN_EXR_MULTILAYER"
scene.render.filepath = sys.argv[2]
bpy.ops.render.render(animation=True)
PY
}

seconds() {
    local start=$(date +%s.%N)
    "$@"
    python3 -c "print(round($(date +%s.%N) - $start, 1))"
}

for round in $(seq "$ROUNDS"); do
    hand=$(seconds by_hand)
    eng=$(seconds engine)
    echo "round $round: by hand ${hand} s, engine ${eng} s, ratio $(python3 -c "print(round($eng / $hand, 2))")"
done
