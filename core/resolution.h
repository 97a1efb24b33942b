#pragma once
// What a cloud must resolve for a scene to be accurate (docs/physics.md §6): the
// smallest contact patch of the verification sweep and every inclusion. The graded
// lattice takes its focus spacing from here when the scene does not give one, and
// scripts/make_mesh.sh --scene sizes a tetrahedral mesh with it (palpate-resolution).
#include <vector>

#include "core/scene.h"
#include "core/types.h"

namespace palpate {

// Spacings across the smallest contact radius, and across an inclusion's radius.
constexpr double kSpacingsPerContactRadius = 3.0;
constexpr double kSpacingsPerInclusionRadius = 6.0;

// An inclusion's ball (a box's: the ball through its corners) and the spacing inside it.
struct RegionResolution {
  Vec3 center{0, 0, 0};  // m
  double radius = 0.0;   // m
  double spacing = 0.0;  // the largest particle spacing that resolves it, m
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
// tissue the tool touches).
Resolution required_resolution(const Scene& scene);

}  // namespace palpate
