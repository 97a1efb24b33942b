#!/usr/bin/env bash
# Set-up, build (Release with assertions kept), and the whole test suite through ctest.
#
#   scripts/test.sh [CTEST ARGS]   Release build in build/ (or $BUILD_DIR), the whole suite: first every
#                                  test but the wall-clock ones, then those (ctest label `timing`)
#     Timing tests (label `timing`, docs/robustness.md): the gtest cases of suites named *Timing
#     hold rates and latencies to wall-clock thresholds (server_e2e_timing, server_security_timing,
#     agones_e2e_timing, SimulationTiming.*). They run by default, serially, after the rest. With
#     CI=true (a shared runner) their failure is reported ("timing tests failed on a noisy host
#     (not a defect)") and does not fail the suite; everywhere else it does.
#   scripts/test.sh --sanitize     the robustness suite (docs/robustness.md), 27-31 min on 2 cores (7 December 2026):
#     1. AddressSanitizer + UndefinedBehaviorSanitizer build of what the suite runs in build-asan/,
#        the whole suite (UBSan stops at the first report, LeakSanitizer at exit);
#     2. ThreadSanitizer build of the server and its e2e test in build-tsan/, that test;
#     3. the libFuzzer targets (clang, fuzz/) in build-fuzz/, each run for
#        $FUZZ_SECONDS (20) seconds from its seed corpus, and their regressions.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" != "--sanitize" ]; then
  export BUILD_DIR=${BUILD_DIR:-build}
  scripts/build.sh
  cd "$BUILD_DIR"
  # As in the sanitized runs below: the e2e tests run real-time sessions against the wall
  # clock on a shared machine (one late tick fails the command-latency test), so a test that
  # fails is run once more and the suite fails only if it fails twice; the log shows every
  # failure. A deterministic test that fails fails twice.
  ctest --output-on-failure -j"$(nproc)" --repeat until-pass:2 -LE timing "$@"
  # The wall-clock tests last, on a machine the suite no longer loads (they are RUN_SERIAL).
  if ! ctest --output-on-failure --repeat until-pass:2 -L timing "$@"; then
    if [ "${CI:-}" = true ]; then
      echo "test.sh: timing tests failed on a noisy host (not a defect): the ctest label 'timing' above" \
        "(wall-clock thresholds, docs/robustness.md); the rest of the suite passed"
      exit 0
    fi
    exit 1
  fi
  exit
fi

scripts/setup.sh
source scripts/lib/configure.sh
jobs=$(nproc)
# -O1 -g1 (line tables), assertions on: half the compile time of RelWithDebInfo, file:line in reports.
flags=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1")
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:check_initialization_order=1:strict_init_order=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1
step() { echo "== test.sh --sanitize: $* ($(date +%T))"; }

step "ASan + UBSan build (build-asan)"
palpate_configure build-asan "${flags[@]}" -DPALPATE_SANITIZE=address,undefined
# Only what the suite runs (the palpate-tests target, tests/CMakeLists.txt): the benchmarks
# and tools no test starts are left out, which saves minutes of sanitized compiling.
cmake --build build-asan -j"$jobs" --target palpate-tests
# The wall-clock tests that a sanitized build cannot meet stay in the Release suite: the
# sanitized builds leave them out of their `timing` entries (palpate_sanitized_wall_clock in
# tests/CMakeLists.txt: the stalled-client e2e tests, the command-latency test, the overload
# test). (The palpate-stress smoke run, which outgrows its 120 s limit at ASan's speed, and the
# reference recomputation are not registered in sanitized builds.)
# The e2e tests that remain, `timing` ones included, still run a real-time session against the
# wall clock: a test that fails is run once more (ctest --repeat until-pass:2) and the suite
# fails only if it fails twice; the log shows every failure.
(cd build-asan && ctest --output-on-failure -j"$jobs" --repeat until-pass:2)

step "TSan build of the server and its e2e test (build-tsan)"
palpate_configure build-tsan "${flags[@]}" -DPALPATE_SANITIZE=thread
cmake --build build-tsan -j"$jobs" --target palpate-server server_e2e_test
# The same for ThreadSanitizer (5-15x slower).
(cd build-tsan && ctest --output-on-failure -R '^server_e2e(_timing)?$' --repeat until-pass:2)

step "libFuzzer targets (build-fuzz, clang)"
CC=clang CXX=clang++ palpate_configure build-fuzz "${flags[@]}" -DPALPATE_FUZZ=ON \
  -DPALPATE_SANITIZE=address,undefined -DPALPATE_FUZZ_SECONDS="${FUZZ_SECONDS:-20}"
cmake --build build-fuzz -j"$jobs" --target palpate-fuzzers
(cd build-fuzz && ctest --output-on-failure -j"$jobs" -L fuzz)
step "done"
