#pragma once
// Tetrahedral meshes read from files: the vertices become the particles of a
// meshless cloud (the paper's tetrahedralisation-vertex clouds), the tetrahedra
// give each particle its nodal volume.
//
// Formats (the format follows the extension):
//   .msh   gmsh ASCII, version 4.1 (entity blocks, node tags) or 2.2. Only
//          4-node tetrahedra (element type 4) are kept; points, lines, triangles
//          and every other element type are ignored. $PhysicalNames, $Entities
//          and any other section are skipped. Binary files and version 4.0 are refused.
//   .node  TetGen: the .node file and its sibling .ele (same stem). Indices are
//          0- or 1-based as the first point of the .node file says; attributes and
//          boundary markers are read and ignored; '#' starts a comment; 10-node
//          .ele files keep their four corners.
//
// Nodal volumes (the tetrahedra's lumped volumes): v_i = sum over the tetrahedra t
// incident to node i of |V_t| / 4, V_t = det[x_b - x_a, x_c - x_a, x_d - x_a] / 6,
// so sum_i v_i = sum_t |V_t|, the volume of the meshed body.
//
// Orientation: a file's tetrahedra must all have the same orientation (the sign of
// V_t). gmsh writes them positive; a mirrored mesh, or a generator with the other
// convention, has them all negative: either is accepted and stored positive (the
// second and third node swapped). A tetrahedron
// whose sign differs from the file's first one is inverted (a tangled mesh) and
// refused, as is a degenerate one (|V_t| <= 1e-12 L^3, L its longest edge).
//
// Nodes used by no tetrahedron (gmsh's geometry points, the mid-edge nodes of
// quadratic elements) are dropped and counted. Every refusal is a
// std::runtime_error "<file>:<line>: <reason>" (no line when the whole file is
// concerned): malformed or non-finite numbers, missing sections or counts that do
// not match, indices out of range, duplicate tags, coincident nodes, degenerate or
// inverted tetrahedra, more than `max_nodes` nodes.
#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "core/types.h"

namespace palpate {

// The largest mesh a scene may name: 200^3 nodes, the largest lattice (per_edge <= 200).
constexpr int64_t kMaxMeshNodes = 200LL * 200 * 200;

struct TetMesh {
  Points positions;                            // 3 x n nodes used by a tetrahedron, in file order, m
  std::vector<std::array<int, 4>> tetrahedra;  // m x 4 indices into positions, V_t > 0
  std::vector<double> nodal_volume;            // n, v_i = sum_t |V_t| / 4 over incident t, m^3
  double total_volume = 0.0;                   // sum_t |V_t| (= sum_i v_i), m^3
  int64_t unused_nodes = 0;                    // nodes of the file used by no tetrahedron (dropped)
  int64_t ignored_elements = 0;                // gmsh: elements that are not 4-node tetrahedra
  bool reoriented = false;                     // the file's tetrahedra were negative (now swapped)
};

// gmsh .msh (4.1 or 2.2 ASCII).
TetMesh read_gmsh(const std::filesystem::path& file, int64_t max_nodes = kMaxMeshNodes);
// TetGen: `node_file` (.node) and the .ele next to it.
TetMesh read_tetgen(const std::filesystem::path& node_file, int64_t max_nodes = kMaxMeshNodes);
// By extension: .msh -> read_gmsh, .node -> read_tetgen; anything else is refused.
TetMesh read_mesh(const std::filesystem::path& file, int64_t max_nodes = kMaxMeshNodes);

// The .ele file that goes with a TetGen .node file (same stem).
std::filesystem::path tetgen_element_file(const std::filesystem::path& node_file);
// True for the extensions read_mesh knows (.msh, .node).
bool known_mesh_extension(const std::filesystem::path& file);

// The node count a mesh file declares in its header ($Nodes of gmsh, the first line
// of a TetGen .node), read without reading the nodes: an upper bound on the
// particles, for refusing oversized meshes before loading them. Throws like the readers.
int64_t declared_mesh_nodes(const std::filesystem::path& file);

}  // namespace palpate
