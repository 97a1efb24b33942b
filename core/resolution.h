#pragma once
// What a cloud must resolve for a scene to be accurate (docs/physics.md §6): the
// smallest contact patch of the verification sweep and every inclusion. The graded
// lattice takes its focus spacing from here when the scene does not give one, and
// scripts/make_mesh.sh --scene sizes a tetrahedral mesh with it (palpate-resolution).
#include <string>
#include <vector>

#include "core/mesh_reader.h"
#include "core/scene.h"
#include "core/types.h"

namespace palpate {

// Spacings across the smallest contact radius, and across an inclusion's radius.
constexpr double kSpacingsPerContactRadius = 3.0;
constexpr double kSpacingsPerInclusionRadius = 6.0;

// An inclusion's ball (a box's: the ball through its corners; a mesh group's: the ball around
// its tetrahedra from their centroid) and the spacing inside it.
struct RegionResolution {
  Vec3 center{0, 0, 0};  // m
  double radius = 0.0;   // m
  double spacing = 0.0;  // the largest particle spacing that resolves it, m
  std::string group;          // a group inclusion: the mesh's physical volume (empty: a sphere or a box)
  double mesh_spacing = 0.0;  // a group: the mean edge of its tetrahedra, the spacing the mesh has there, m
};

struct Resolution {
  double smallest_force = 0.0;           // N, the smallest force of the scene's sweep (verify.forces)
  double smallest_depth = 0.0;           // m, its Hertz depth (6.1)
  double smallest_contact_radius = 0.0;  // m, a_min = sqrt(R d_min) (6.1)
  double contact_spacing = 0.0;          // m, a_min / kSpacingsPerContactRadius (6.2)
  std::vector<RegionResolution> inclusions;  // each inclusion: radius / kSpacingsPerInclusionRadius (6.3)
  // The finest spacing any of the above asks for, m.
  double finest_spacing() const;
};

// The resolution the scene's tool, sweep and material ask for (the matrix material: the
// tissue the tool touches). Group inclusions (a physical volume of the body's mesh) are left
// out here: their size is in the mesh, which the overload below reads.
Resolution required_resolution(const Scene& scene);

// The same with the group inclusions too, in the scene's order, from `mesh`, the body's mesh
// (scene.distribution.mesh_file, read): a group is sized by its volume V and boundary area A as a
// ball of radius 3V/A (a ball's own radius; a cube's half-edge), spanned by
// kSpacingsPerInclusionRadius spacings, and reported with the spacing the mesh has in it. An
// unknown group name throws std::runtime_error listing the mesh's names.
Resolution required_resolution(const Scene& scene, const TetMesh& mesh);

}  // namespace palpate
