#!/usr/bin/env bash
# Installs the Debian packages palpate needs, only those that are missing.
# Idempotent and silent when everything is already there.
set -euo pipefail
packages=(
  build-essential cmake pkg-config
  ninja-build                 # the generator of new build folders (scripts/lib/configure.sh)
  libeigen3-dev libnanoflann-dev
  capnproto libcapnp-dev
  libspdlog-dev libgtest-dev libbenchmark-dev
  nlohmann-json3-dev          # scene files: JSON parsing with field paths in error messages
  libsuitesparse-dev          # CHOLMOD: the model build's consistent-integration solve (core) and the quasi-static FEM solve (the finite-block reference)
  libopenblas0-serial         # optimised BLAS for CHOLMOD's supernodal factorisation (4x faster than the reference BLAS)
  python3-matplotlib python3-numpy   # plots in docs/ (glue only)
  python3-meshio              # an independent reader of the VTK export (tests/vtk_meshio_test.cpp)
  clang libclang-rt-14-dev    # fuzz/: libFuzzer (libclang_rt.fuzzer) for Debian's clang 14 (test.sh --sanitize)
  chromium                    # the browser viewer's end-to-end test (headless, tests/browser/)
  openssl                     # self-signed certificates for the TLS end-to-end test (tests/e2e/server_security_test.cpp)
)
# node and npm build the browser viewer (clients/viewer: npm ci of its pinned lock file).
# A machine may have them from elsewhere (e.g. a nodejs that bundles npm): only what
# is missing is installed from Debian.
command -v node >/dev/null 2>&1 || packages+=(nodejs)
command -v npm >/dev/null 2>&1 || packages+=(npm)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "setup: installing ${missing[*]}"
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
