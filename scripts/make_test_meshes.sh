#!/usr/bin/env bash
# The test meshes generated from committed .geo files (Debian's gmsh; not needed by the
# build or the tests, which read the committed .msh).
#   tests/data/dome.msh: a hemisphere of radius 0.05 m, physical surfaces "base" and "skin",
#   physical volume "tissue" (tests/mesh_reader_test.cpp, tests/surface_test.cpp).
set -euo pipefail
cd "$(dirname "$0")/.."
command -v gmsh >/dev/null || { echo "gmsh is missing: apt-get install -y gmsh" >&2; exit 1; }
gmsh -3 -order 1 tests/data/dome.geo -o tests/data/dome.msh
#   tests/data/lump_block.msh: a 10 x 10 x 5 cm block with a conformally meshed spherical lump,
#   physical volumes "matrix" and "lump" (tests/material_field_test.cpp).
gmsh -3 -order 1 tests/data/lump_block.geo -o tests/data/lump_block.msh
