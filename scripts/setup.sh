#!/usr/bin/env bash
# Installs the Debian packages slimrt needs, only those missing: dpkg -s first, one apt-get update.
set -euo pipefail
PKGS=(cmake g++ make pkg-config libembree-dev libtbb-dev libtinyobjloader-dev libtinygltf-dev
      libstb-dev libtinyexr-dev zlib1g-dev liblzma-dev libglu1-mesa-dev libcli11-dev
      nlohmann-json3-dev libgtest-dev libbenchmark-dev gnuplot-nox xz-utils libxxhash-dev
      pybind11-dev python3-dev python3-numpy python3-pytest openmpi-bin libopenmpi-dev
      python3-open3d)
# libxxhash-dev: the scene files' section checksums (XXH3-64, src/api/scene_file.cpp).
# pybind11-dev, python3-dev, python3-numpy: the Python module (python/), built for Debian's
# /usr/bin/python3; python3-pytest: its tests (./test.sh). python3-open3d (36 MB download with its
# dependencies, about 1.5 min to install): python/examples/compare_open3d.py and the test that
# checks create_rays_pinhole against Open3D; set SLIM_NO_OPEN3D=1 to leave it out (both skip).
# openmpi-bin, libopenmpi-dev: `mpirun -np K slimrt render` (tools/mpi_render.cpp, the CLI only;
# CMake builds the CLI without MPI when it is missing; the ctest MpiRender skips without mpirun).
if [ "${SLIM_NO_OPEN3D:-0}" = 1 ]; then
  PKGS=("${PKGS[@]/python3-open3d}")
fi
missing=()
for p in "${PKGS[@]}"; do
  [ -n "$p" ] || continue
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y "${missing[@]}"
fi
