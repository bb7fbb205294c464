#!/usr/bin/env bash
# Installs what is missing (Debian 12, as root), builds Release, renders the default scene and
# prints the memory/speed table against Embree.
set -euo pipefail
cd "$(dirname "$0")"
./scripts/setup.sh
./scripts/build.sh
mkdir -p out
./build/slimrt render terrain:1024 -o out/default.png
./build/slimrt info terrain:1024
./build/slimrt bench terrain:1024 --repeat 3
