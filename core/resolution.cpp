#include "core/resolution.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>

#include <Eigen/Geometry>

#include "core/hertz.h"

namespace palpate {

double Resolution::finest_spacing() const {
  double h = contact_spacing;
  for (const RegionResolution& r : inclusions) h = std::min(h, r.spacing);
  return h;
}

namespace {

// A physical volume of `mesh` (the group inclusion `inc`) as a ball and the spacing inside it.
RegionResolution group_resolution(const InclusionSpec& inc, const TetMesh& mesh, const std::filesystem::path& file) {
  const int64_t tag = physical_group_tag(mesh, file, 3, inc.group);
  const Points& X = mesh.positions;
  std::vector<std::array<int, 4>> tets;
  double volume = 0.0, edges = 0.0;
  Vec3 moment = Vec3::Zero();
  for (size_t t = 0; t < mesh.tetrahedra.size(); ++t) {
    if (mesh.tetrahedron_region[t] != tag) continue;
    const auto& v = mesh.tetrahedra[t];
    tets.push_back(v);
    const Vec3 a = X.col(v[0]), b = X.col(v[1]), c = X.col(v[2]), d = X.col(v[3]);
    const double V = std::abs((b - a).dot((c - a).cross(d - a))) / 6.0;
    volume += V;
    moment += V * 0.25 * (a + b + c + d);
    edges += (b - a).norm() + (c - a).norm() + (d - a).norm() + (c - b).norm() + (d - b).norm() + (d - c).norm();
  }
  RegionResolution r;
  r.group = inc.group;
  if (tets.empty()) return r;  // a named volume without tetrahedra: nothing to resolve
  r.center = moment / volume;
  for (const auto& v : tets)
    for (int k : v) r.radius = std::max(r.radius, (X.col(k) - r.center).norm());
  double area = 0.0;
  for (const auto& f : tetrahedra_boundary_faces(X, tets))
    area += 0.5 * (X.col(f[1]) - X.col(f[0])).cross(X.col(f[2]) - X.col(f[0])).norm();
  r.spacing = 3.0 * volume / area / kSpacingsPerInclusionRadius;  // (6.3) with the ball's radius 3V/A
  r.mesh_spacing = edges / (6.0 * static_cast<double>(tets.size()));
  return r;
}

Resolution resolution_of(const Scene& scene, const TetMesh* mesh) {
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
    if (inc.shape == InclusionShape::group) {
      if (!mesh) continue;  // its size is in the mesh
      const RegionResolution r = group_resolution(inc, *mesh, scene.distribution.mesh_file);
      if (r.spacing > 0) out.inclusions.push_back(r);
      continue;
    }
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

}  // namespace

Resolution required_resolution(const Scene& scene) { return resolution_of(scene, nullptr); }

Resolution required_resolution(const Scene& scene, const TetMesh& mesh) { return resolution_of(scene, &mesh); }

}  // namespace palpate
