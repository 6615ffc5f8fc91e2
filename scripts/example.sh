#!/usr/bin/env bash
# The main job on the built-in example: make a neural asset, validate it, inspect it and render it.
# Outputs go to ./out/ (asset .usdc, render .exr and .png).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
N=.venv/bin/nasset
$N example --kind rna --size small -o out/example.usdc
$N validate out/example.usdc
$N inspect out/example.usdc
$N render out/example.usdc -o out/example.exr --png out/example.png --spp 16 --width 256 --height 256
echo "done: out/example.usdc, out/example.exr, out/example.png"
