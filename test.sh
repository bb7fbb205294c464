#!/usr/bin/env bash
# Installs what is missing (Debian 12, as root), builds Release and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")"
./scripts/setup.sh
./scripts/build.sh
cd build && ctest --output-on-failure -j"$(nproc)"
