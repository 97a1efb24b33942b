#pragma once
// Tetrahedral meshes read from files: the vertices become the particles of a
// meshless cloud (the paper's tetrahedralisation-vertex clouds), the tetrahedra
// give each particle its nodal volume.
//
// Formats (the format follows the extension):
//   .msh   gmsh ASCII, version 4.1 (entity blocks, node tags) or 2.2. Only 4-node
//          tetrahedra (element type 4) become the body; 3-node triangles (type 2) of a
//          physical surface group give that group's node set (TetMesh::surface_groups);
//          points, lines and every other element type are ignored. $PhysicalNames is
//          read (TetMesh::physical_names); in 4.1 $Entities gives each entity's physical
//          tags (an element's physical groups are its entity's), in 2.2 an element's
//          first tag is its physical group. Any other section is skipped. Binary files
//          and version 4.0 are refused. A tetrahedron's region (tetrahedron_region) is
//          its first physical volume tag, 0 when it has none.
//   .node  TetGen: the .node file and its sibling .ele (same stem). Indices are
//          0- or 1-based as the first point of the .node file says; node attributes
//          and boundary markers are read and ignored; '#' starts a comment; 10-node
//          .ele files keep their four corners. The first region attribute of an .ele
//          line (when the header declares attributes) is the tetrahedron's region
//          (rounded to an integer); none: 0.
//
// Nodal volumes (the tetrahedra's lumped volumes): v_i = sum over the tetrahedra t
// incident to node i of |V_t| / 4, V_t = det[x_b - x_a, x_c - x_a, x_d - x_a] / 6,
// so sum_i v_i = sum_t |V_t|, the volume of the meshed body.
//
// The checks (after reading; each refusal names the element or node by its number
// in the file and the line that defines it):
//   degenerate  a tetrahedron with a repeated node or |V_t| <= 1e-12 L^3, L its
//               longest edge. Relative to L^3 so that the rule does not depend on the
//               units or the mesh size. A regular tetrahedron has 0.118 L^3; the worst
//               element of the shipped gmsh meshes has 0.014 L^3. 1e-12 L^3 is about
//               4500 round-offs (2.2e-16 L^3) of the determinant, so for coordinates
//               up to ~1000 L from the origin it refuses only elements whose volume is
//               lost in round-off (four nodes in one plane), never a merely poor one;
//   inverted    a tetrahedron whose sign of V_t differs from the file's orientation.
//               gmsh's convention (its reference tetrahedron (0,0,0), (1,0,0), (0,1,0),
//               (0,0,1)) is V_t > 0: node d on the side toward which a, b, c turn
//               counterclockwise. The file's orientation is the sign most of its
//               tetrahedra have (ties: positive), so a mirrored file or a generator
//               with the other convention, all negative, is accepted and stored
//               positive (the second and third node swapped; `reoriented`); an
//               element of the minority sign is a tangled or misnumbered one;
//   unused node a node no tetrahedron references (a gmsh geometry point, the nodes
//               of surface elements of a part not meshed in volume): refused, not
//               dropped, since it is a particle the file meant to have or a file
//               that does not describe one body. The mid-edge nodes of a TetGen
//               10-node .ele are referenced and dropped (counted in `unused_nodes`);
//   coincident  two kept nodes at the same point (a crack);
//   overlap     a triangle shared by more than two tetrahedra (duplicated or
//               overlapping elements);
//   parts       the tetrahedra must form one part connected through shared faces
//               (triangles): parts touching only at an edge or a node are refused
//               too (a pinch, no body in between);
//   names       $PhysicalNames: each entry "dimension tag \"name\"", dimension 0..3,
//               tag >= 1, a non-empty name on one line; a (dimension, tag) or a
//               (dimension, name) given twice is refused.
// Boundary faces: the triangles that belong to exactly one tetrahedron, each ordered
// so that (x_b - x_a) x (x_c - x_a) points out of the body (away from the fourth node of
// its tetrahedron): counterclockwise seen from outside.
//
// Every refusal is a std::runtime_error "<file>:<line>: <reason>" (no line when the
// whole file is concerned): malformed or non-finite numbers, missing sections or
// counts that do not match, indices out of range, duplicate tags, the checks above,
// more than `max_nodes` nodes.
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/types.h"

namespace palpate {

// The largest mesh a scene may name: 200^3 nodes, the largest lattice (per_edge <= 200).
constexpr int64_t kMaxMeshNodes = 200LL * 200 * 200;

// One $PhysicalNames entry of a gmsh file: the physical group of `dimension` (0 points,
// 1 curves, 2 surfaces, 3 volumes) numbered `tag`, called `name`.
struct PhysicalName {
  int dimension = 0;
  int64_t tag = 0;
  std::string name;
  int line = 0;  // the file line of the entry
};

// The nodes of the triangles of one gmsh physical surface group.
struct SurfaceGroup {
  int64_t tag = 0;         // the physical tag
  std::string name;        // its $PhysicalNames name ("" when unnamed)
  std::vector<int> nodes;  // indices into TetMesh::positions, ascending, unique
};

struct TetMesh {
  Points positions;                            // 3 x n nodes used by a tetrahedron, in file order, m
  std::vector<std::array<int, 4>> tetrahedra;  // m x 4 indices into positions, V_t > 0
  std::vector<double> nodal_volume;            // n, v_i = sum_t |V_t| / 4 over incident t, m^3
  double total_volume = 0.0;                   // sum_t |V_t| (= sum_i v_i), m^3
  int64_t unused_nodes = 0;                    // TetGen 10-node .ele: the mid-edge nodes (dropped); else 0
  int64_t ignored_elements = 0;                // gmsh: elements that are not 4-node tetrahedra
  bool reoriented = false;                     // the file's tetrahedra were negative (now swapped)
  std::vector<PhysicalName> physical_names;    // gmsh $PhysicalNames in file order (TetGen: none)
  std::vector<int64_t> tetrahedron_region;     // m, the physical volume tag (TetGen: region attribute), 0 = none
  std::vector<SurfaceGroup> surface_groups;    // gmsh physical surface groups with triangles, by ascending tag
  std::vector<std::array<int, 3>> boundary_faces;  // triangles of one tetrahedron only, outward (see above)
};

// The node set of the physical surface group named `name`: unknown names are refused
// by physical_group_tag's message; a named group without triangles has no nodes.
const std::vector<int>& surface_group_nodes(const TetMesh& mesh, const std::filesystem::path& file,
                                            std::string_view name);

// The tag of the physical group of `dimension` named `name` in `mesh` (read from
// `file`, for the message); an unknown name is a std::runtime_error
// "<file>: no physical group of dimension D is named 'x' (the file names: ...)".
int64_t physical_group_tag(const TetMesh& mesh, const std::filesystem::path& file, int dimension,
                           std::string_view name);

// The faces of exactly one of `tets`, each ordered so that its normal (x_b - x_a) x (x_c - x_a)
// points away from its tetrahedron's fourth node (outward): TetMesh::boundary_faces.
std::vector<std::array<int, 3>> tetrahedra_boundary_faces(const Points& X, const std::vector<std::array<int, 4>>& tets);

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
