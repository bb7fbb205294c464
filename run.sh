#!/usr/bin/env bash
# Installs what is missing (Debian 12, as root), builds Release, renders the default scene
# (canyon:1024 under a low sun, the picture of docs/images/default.png) to out/default.png,
# prints its statistics and the memory/speed table against Embree on terrain:1024 (the main
# configuration of each technique; `slimrt bench terrain:1024` runs them all).
set -euo pipefail
cd "$(dirname "$0")"
./scripts/setup.sh
./scripts/build.sh
mkdir -p out
./build/slimrt render canyon:1024 --config lossy-grid-shared --shade sun --spp 16 --res 1280x720 \
  -o out/default.png
./build/slimrt info canyon:1024 --accel lossy-grid-shared
./build/slimrt bench terrain:1024 --repeat 3 --json out/default-bench.json --plot out/default-bench.png \
  --config embree-tri,embree-tri-compact,embree-quad,embree-grid,bvh8-tri4v,bvh8-tri4i,qbvh8-tri4v \
  --config clbvh-tri4v,clbvh-compact,bvh8-pairs,clbvh-pairs,grid,lossy-grid,lossy-grid-e2,lossy-grid-shared,costa-PFV,cluster,cluster-lossless
