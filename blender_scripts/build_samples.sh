#!/usr/bin/env bash
# Rebuilds the Blender sample scenes in gbuffers/ from nothing: each scene is built by its
# script in blender_scripts/scenes/, exported with export_scene.py, rendered by Cycles
# with direct lighting only (render_cycles.py), and finally compared with logsh
# (examples/cycles_compare.rs), whose table goes into docs/accuracy.md.
#
#     bash blender_scripts/build_samples.sh [OUT_DIR]     # default: gbuffers
#
# Needs Blender as a Python module: the interpreter is $LOGSH_BPY_PYTHON, else
# .venv-bpy/bin/python (made by .ci/bpy-setup), else python3. Each scene is built in a
# temporary directory and moved into OUT_DIR/<name> only when complete, replacing the
# previous build of that scene (these directories are this script's products).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-gbuffers}
PYTHON=${LOGSH_BPY_PYTHON:-}
if [ -z "$PYTHON" ]; then
    if [ -x .venv-bpy/bin/python ]; then PYTHON=.venv-bpy/bin/python; else PYTHON=python3; fi
fi
"$PYTHON" -c "import bpy" || { echo "error: $PYTHON cannot import bpy (run .ci/bpy-setup)" >&2; exit 1; }

RESOLUTION=240x135   # about 0.9 MB per frame of G-buffer (float32 position and normal, ZIP)
SAMPLES=512          # Cycles samples per pixel for the reference
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

build() {  # name, frames, extra export options...
    local name=$1 frames=$2
    shift 2
    echo "== $name"
    "$PYTHON" blender_scripts/scenes/"$name".py --save "$WORK/$name.blend"
    # Without colour passes: each sample is compared with render_cycles.py's converted
    # materials (cycles.0001.exr), the truth for the method.
    "$PYTHON" blender_scripts/export_scene.py --blend "$WORK/$name.blend" --out "$WORK/$name" \
        --frames "$frames" --resolution $RESOLUTION --no-colour-passes "$@"
    "$PYTHON" blender_scripts/render_cycles.py --blend "$WORK/$name.blend" --out "$WORK/$name" \
        --samples $SAMPLES --resolution $RESOLUTION
    mkdir -p "$OUT"
    rm -rf "${OUT:?}/$name"
    mv "$WORK/$name" "$OUT/$name"
}

build dunes 1-2 --heightmap-size 97
build wrecking_ball 1-3
build cones 1-2
du -sh "$OUT"/*
cargo run --release --example cycles_compare -- "$OUT/dunes" "$OUT/wrecking_ball" "$OUT/cones"
