# shellcheck shell=bash
# The one configure step of scripts/build.sh and scripts/test.sh, sourced by them:
#
#   palpate_configure DIR [CMAKE ARGS...]   cmake -S . -B DIR ARGS (its output hidden)
#
# A new build folder gets the Ninja generator (Debian's ninja-build, from scripts/setup.sh):
# it compiles a target's sources while the libraries the target links are still being built,
# where Make waits for each library whole, so that one long file (the force loops') does not
# hold back every target that links its library. A folder configured before keeps the
# generator it has (CMake refuses to change it).
palpate_configure() {
  local dir=$1
  shift
  local generator=()
  [ -f "$dir/CMakeCache.txt" ] || generator=(-G Ninja)
  cmake -S . -B "$dir" "${generator[@]}" "$@" >/dev/null
}
