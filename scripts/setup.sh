#!/usr/bin/env bash
# Installs the Debian packages slimrt needs, only those missing: dpkg -s first, one apt-get update.
set -euo pipefail
PKGS=(cmake g++ make pkg-config libembree-dev libtbb-dev libtinyobjloader-dev libtinygltf-dev
      libstb-dev libtinyexr-dev zlib1g-dev liblzma-dev libglu1-mesa-dev libcli11-dev
      nlohmann-json3-dev libgtest-dev libbenchmark-dev gnuplot-nox xz-utils)
missing=()
for p in "${PKGS[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y "${missing[@]}"
fi
