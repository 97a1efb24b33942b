#pragma once
// Node distributions: where the particles of the meshless solid sit in the
// reference configuration.
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/mesh_reader.h"
#include "core/scene.h"
#include "core/types.h"

namespace palpate {

struct NodeCloud {
  Points positions;                   // 3 x n reference positions X_i, m
  std::vector<double> lattice_volume; // n geometric cell volumes (lattices only; else empty), m^3
  Eigen::Vector3i lattice_size{0, 0, 0};  // nodes per axis for lattices, 0 otherwise
  // Tetrahedral meshes only (else empty / 0): v_i = a quarter of each incident tetrahedron.
  std::vector<double> mesh_volume;    // n, m^3
  int64_t mesh_tetrahedra = 0;        // tetrahedra of the mesh
  int64_t mesh_unused_nodes = 0;      // TetGen mid-edge nodes dropped (other unused nodes are refused: mesh_reader.h)
  std::vector<std::array<int, 4>> tetrahedra;        // mesh_tetrahedra x 4 particle indices, positive volume
  std::vector<int64_t> tetrahedron_region;           // their physical volume tag (TetGen: region), 0 = none
  struct NodeSet {
    std::string name;        // the gmsh physical surface name ("" when unnamed)
    int64_t tag = 0;         // its physical tag
    std::vector<int> nodes;  // particle indices, ascending
  };
  std::vector<NodeSet> surface_node_sets;            // the mesh's physical surface groups
  struct VolumeGroup {
    std::string name;  // the gmsh physical volume name
    int64_t tag = 0;   // its tag in tetrahedron_region
  };
  std::vector<VolumeGroup> volume_groups;            // the mesh's named physical volumes ($PhysicalNames)
  std::vector<std::array<int, 3>> boundary_triangles;  // the mesh's boundary faces, outward (mesh_reader.h)
  // A cloud refined in-process (refined_mesh_cloud): particles [0, refined_from) are the base
  // mesh's vertices, the others the refinement's; 0 for any other cloud.
  int refined_from = 0;
};

// Regular lattice with `per_axis` nodes along each box axis, corners included.
NodeCloud grid_nodes(const BoxSpec& box, const Eigen::Vector3i& per_axis);
// Nodes per axis for a target spacing: round(edge / spacing) + 1 on each axis.
Eigen::Vector3i nodes_per_axis(const BoxSpec& box, double spacing);
// The lattice with every node displaced by a seeded uniform random offset of at
// most jitter * spacing per component; nodes on a face stay on it.
NodeCloud jittered_grid_nodes(const BoxSpec& box, const Eigen::Vector3i& per_axis, double jitter,
                              uint64_t seed);
// The ratio r > 0 of the geometric series first (1 + r + ... + r^(intervals-1)) = length.
double geometric_ratio(double first, double length, int intervals);
// Coordinates of `count` nodes on [lo, hi] graded geometrically away from `focus`:
// the two intervals next to the focus (one if it lies on an end) are `first_spacing`
// long, the following ones grow by a constant ratio per side. Throws
// std::invalid_argument when the spacing does not fit.
std::vector<double> graded_axis(double lo, double hi, double focus, int count, double first_spacing);
// Tensor-product lattice of three graded axes (per_axis nodes each), with lattice volumes.
NodeCloud graded_grid_nodes(const BoxSpec& box, const Eigen::Vector3i& per_axis, const Vec3& focus,
                            double first_spacing);
// The focus of a scene's graded lattice: distribution.focus, else the top-face point
// under the indenter's start (the centre of the top face by default).
Vec3 graded_focus(const Scene& scene);
// Plain node list: "x y z" per line; blank lines and lines starting with '#' are
// skipped. Throws std::runtime_error naming file, line and reason.
NodeCloud load_node_list(const std::filesystem::path& file);

// The vertices of the tetrahedral mesh distribution.mesh_file (core/mesh_reader.h) with
// their nodal volumes, tetrahedra, regions, physical surface node sets and boundary faces.
// With /body/box given (Scene::box_given) the mesh must fill it: its bounding box and the
// tetrahedra's total volume must equal the box's to 1e-6 (relative), else a SceneError at
// /body/distribution/file; without it the mesh may have any shape (a dome, a sphere).
// Reader errors are std::runtime_error naming file and line.
NodeCloud mesh_node_cloud(const Scene& scene);

// The tool's centre a scene starts with: indenter.position, else over the centre of the
// mesh's bounding box, one radius above its top (build_model places it there).
Vec3 tool_centre(const Scene& scene, const TetMesh& mesh);
// The point a mesh's refinement aims at when the tool's centre is `tool`: distribution.focus
// when given, else the point of the base's boundary surface nearest the tool.
Vec3 refinement_focus(const Scene& scene, const TetMesh& base, const Vec3& tool);
// The cloud of a mesh, as it is (its nodes, nodal volumes, tetrahedra and surface groups).
NodeCloud mesh_cloud(const TetMesh& mesh);
// The cloud of a mesh distribution from its (already read and checked) base mesh: the base
// itself, or with distribution.refine the base refined (core/mesh_refinement.h) toward
// distribution.focus when given, else toward the point of the body's surface nearest `tool`
// (the tool's centre, m). Throws SceneError at /body/distribution/refine/size when the
// refinement passes the node limit.
NodeCloud refined_mesh_cloud(const Scene& scene, const TetMesh& base, const Vec3& tool);

// The cloud a scene names (grid, jittered_grid, graded_grid, node_file or mesh).
NodeCloud make_node_cloud(const Scene& scene);

}  // namespace palpate
