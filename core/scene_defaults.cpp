// The defaults a scene file may leave to the reader that depend on the rest of the scene
// (scene_sections.h, docs/scene-format.md): derived once every section is read.
#include "core/scene_sections.h"

#include <stdexcept>
#include <string>

#include "core/hertz.h"
#include "core/node_cloud.h"
#include "core/resolution.h"

namespace palpate {

namespace scene_io {

namespace {

// The defaults that scale with the scene (a field left out or written as 0 / []): the
// contact tolerance, the rest speed and the verification sweep, from the indenter radius R
// (docs/scene-format.md writes the formulas).
void derive_scale_defaults(Scene& s) {
  const double R = s.indenter.radius;
  if (s.contact.tolerance == 0.0) s.contact.tolerance = kContactToleranceOverRadius * R;
  if (s.verify.rest.velocity_tolerance == 0.0)
    s.verify.rest.velocity_tolerance = kRestTravelOverRadius * R / s.verify.rest.window;
  if (s.verify.forces.empty()) s.verify.forces = default_verify_forces(s.material, R);
}

// A graded lattice must fit its box: the focus inside, the first spacing shorter than
// every side it grades.
void check_graded_grid(const Reader& r, const Scene& s) {
  const Vec3 focus = graded_focus(s);
  constexpr char kAxis[] = "xyz";
  for (int a = 0; a < 3; ++a)
    if (!(focus[a] >= s.box.min[a] && focus[a] <= s.box.max[a]))
      r["focus"].fail(std::string("the focus must lie in the box (") + kAxis[a] + " = " + format_number(focus[a]) +
                      " is outside [" + format_number(s.box.min[a]) + ", " + format_number(s.box.max[a]) + "])");
  const Eigen::Vector3i per_axis = s.distribution.spacing > 0 ? nodes_per_axis(s.box, s.distribution.spacing)
                                                              : Eigen::Vector3i::Constant(s.distribution.per_edge);
  for (int a = 0; a < 3; ++a) {
    try {
      graded_axis(s.box.min[a], s.box.max[a], focus[a], per_axis[a], s.distribution.first_spacing);
    } catch (const std::invalid_argument& e) {
      r["first_spacing"].fail(std::string(e.what()).substr(std::string("graded lattice: ").size()) + " along " +
                              kAxis[a]);
    }
  }
}

}  // namespace

void derive_defaults(const Reader& r, Scene& s) {
  derive_scale_defaults(s);
  // A refine object without a size: the spacing the scene asks for (as graded_grid's
  // first_spacing); ignored unless the distribution is a mesh.
  if (s.distribution.refine.size == kDeriveRefineSize)
    s.distribution.refine.size =
        s.distribution.type == DistributionType::mesh ? required_resolution(s).finest_spacing() : 0.0;
  if (s.distribution.type == DistributionType::graded_grid) {
    // Left out (0): the spacing the scene's sweep asks for (core/resolution.h).
    if (s.distribution.first_spacing == 0.0) s.distribution.first_spacing = required_resolution(s).finest_spacing();
    check_graded_grid(r["body"]["distribution"], s);
  }
}

}  // namespace scene_io

std::vector<double> default_verify_forces(const MaterialSpec& material, double radius) {
  const double E_star = hertz::effective_modulus(material.young_modulus, material.poisson_ratio);
  std::vector<double> forces;
  const double lo = kVerifyDepthsOverRadius[0], hi = kVerifyDepthsOverRadius[1];
  for (int k = 0; k < 10; ++k) forces.push_back(hertz::force((lo + (hi - lo) * k / 9.0) * radius, radius, E_star));
  return forces;
}

}  // namespace palpate
