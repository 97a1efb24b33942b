#!/usr/bin/env bash
# Set-up, Release build, then the main job: the Hertz verification sweep of the
# default scene (the paper's 2 m cube, 18^3 = 5832 particles, RK4 at dt = 1 ms),
# printing force, simulated and theoretical indentation and the errors.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
BUILD_DIR=${BUILD_DIR:-build}
echo "== building (Release) in $BUILD_DIR"
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$BUILD_DIR" -j"$(nproc)" >/dev/null
echo "== palpate-verify on scenes/hertz_cube.json"
exec "$BUILD_DIR/bin/palpate-verify" --scene scenes/hertz_cube.json "$@"
