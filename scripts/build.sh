#!/usr/bin/env bash
# Set-up and build: the Debian packages that are missing (scripts/setup.sh), then a
# CMake build in $BUILD_DIR (default build) of type $BUILD_TYPE (default Release).
# demo.sh, test.sh and the container image (deploy/Containerfile) build through it.
#
#   scripts/build.sh                      every target
#   scripts/build.sh palpate-server ...   only these targets (and what they need)
#
# Environment: BUILD_DIR, BUILD_TYPE, JOBS (default: the number of cores), CMAKE_FLAGS
# (more configure options, split at spaces, after -DPALPATE_ARCH=auto: the instruction set
# of this machine, AVX-512 where it has it; -DPALPATE_ARCH=x86-64-v3 for a build that runs
# elsewhere, none for CPUs without AVX2: CMakeLists.txt).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh >&2  # what it installs shows even when the build output is hidden
BUILD_DIR=${BUILD_DIR:-build}
read -ra flags <<< "${CMAKE_FLAGS:-}"
source scripts/lib/configure.sh
palpate_configure "$BUILD_DIR" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" -DPALPATE_ARCH=auto "${flags[@]}"
targets=()
for target in "$@"; do targets+=(--target "$target"); done
cmake --build "$BUILD_DIR" -j"${JOBS:-$(nproc)}" "${targets[@]}"
