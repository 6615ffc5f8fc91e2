#!/usr/bin/env bash
# The main job on the built-in example: bake an rna neural asset from the embedded Mitsuba scene
# (Mitsuba ground truth -> PyTorch training -> ONNX + tensors in USD), validate and inspect it,
# convert the rest of the scene to USD with the asset in place, and render it with the reference
# renderer. Outputs in ./out/. NASSET_SIZE=tiny for a one-minute run (default: small).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
N=.venv/bin/nasset
SIZE=${NASSET_SIZE:-small}
$N bake --example --kind rna --size "$SIZE" -o out/example.usdc
$N validate out/example.usdc
$N inspect out/example.usdc
$N convert-scene --example -o out/scene.usda --replace shell,jelly=out/example.usdc
$N render out/scene.usda -o out/example.exr --png out/example.png --spp 32
echo "done: out/example.usdc (asset), out/scene.usda (scene), out/example.exr + out/example.png (render)"
