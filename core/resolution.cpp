#include "core/resolution.h"

#include <algorithm>
#include <cmath>

#include "core/hertz.h"

namespace palpate {

double Resolution::finest_spacing() const {
  double h = contact_spacing;
  for (const RegionResolution& r : inclusions) h = std::min(h, r.spacing);
  return h;
}

Resolution required_resolution(const Scene& scene) {
  Resolution out;
  const double R = scene.indenter.radius;
  const double E_star = hertz::effective_modulus(scene.material.young_modulus, scene.material.poisson_ratio);
  const std::vector<double> forces =
      scene.verify.forces.empty() ? default_verify_forces(scene.material, R) : scene.verify.forces;
  out.smallest_force = *std::min_element(forces.begin(), forces.end());
  out.smallest_depth = hertz::depth(out.smallest_force, R, E_star);                // (6.1)
  out.smallest_contact_radius = hertz::contact_radius(out.smallest_depth, R);       // (6.1)
  out.contact_spacing = out.smallest_contact_radius / kSpacingsPerContactRadius;   // (6.2)
  for (const InclusionSpec& inc : scene.material.inclusions) {
    if (inc.shape == InclusionShape::group) continue;  // a mesh's own region: the mesh resolves it already
    RegionResolution r;
    if (inc.shape == InclusionShape::sphere) {
      r.center = inc.center;
      r.radius = inc.radius;
      r.spacing = inc.radius / kSpacingsPerInclusionRadius;  // (6.3)
    } else {  // a box: the ball around it, its smallest half-edge spanned as a sphere's radius
      r.center = 0.5 * (inc.min + inc.max);
      r.radius = 0.5 * (inc.max - inc.min).norm();
      r.spacing = 0.5 * (inc.max - inc.min).minCoeff() / kSpacingsPerInclusionRadius;
    }
    out.inclusions.push_back(r);
  }
  return out;
}

}  // namespace palpate
