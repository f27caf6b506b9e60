#!/bin/sh
# Seeds the fuzz corpora from the sample scenes and a freshly rendered multi-layer EXR.
# Run from the repository root: fuzz/seed.sh
set -eu
mkdir -p fuzz/corpus/scene_json fuzz/corpus/frame_json fuzz/corpus/exr
for scene in gbuffers/*/; do
    name=$(basename "$scene")
    cp "$scene/scene.json" "fuzz/corpus/scene_json/$name.json"
    for f in "$scene"/camera.*.json "$scene"/blockers.*.json; do
        cp "$f" "fuzz/corpus/frame_json/$name-$(basename "$f")"
    done
done
tmp=$(mktemp -d)
cargo run --quiet -- example spheres --width 8 --height 6 --out "$tmp/scene"
cargo run --quiet -- render "$tmp/scene" --progress none --out "$tmp/out"
cp "$tmp/scene/gbuffer.0001.exr" fuzz/corpus/exr/gbuffer-blender5.exr
cp "$tmp/out/render.0001.exr" fuzz/corpus/exr/multilayer.exr
cp gbuffers/dunes/sky.exr fuzz/corpus/exr/sky.exr
cp gbuffers/dunes/reflection.0001.exr fuzz/corpus/exr/reflection.exr
printf '#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 2\n\200\200\200\200\200\200\200\200\200\200\200\200\200\200\200\200' > fuzz/corpus/exr/tiny.hdr
rm -rf "$tmp"
