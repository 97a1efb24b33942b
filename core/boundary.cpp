#include "core/boundary.h"

#include <cmath>

#include "core/scene.h"

namespace palpate {

std::vector<uint8_t> particles_on_faces(const Points& positions, uint32_t faces, double tolerance) {
  const Vec3 lo = positions.rowwise().minCoeff();
  const Vec3 hi = positions.rowwise().maxCoeff();
  const double tol = tolerance * (hi - lo).norm();
  const uint32_t low_bit[3] = {face_x_min, face_y_min, face_bottom};
  const uint32_t high_bit[3] = {face_x_max, face_y_max, face_top};
  std::vector<uint8_t> on(static_cast<size_t>(positions.cols()), 0);
  for (Eigen::Index i = 0; i < positions.cols(); ++i)
    for (int c = 0; c < 3; ++c) {
      if ((faces & low_bit[c]) && std::abs(positions(c, i) - lo[c]) <= tol) on[i] = 1;
      if ((faces & high_bit[c]) && std::abs(positions(c, i) - hi[c]) <= tol) on[i] = 1;
    }
  return on;
}

void fix_region(const NodeCloud& cloud, const FixedRegion& region, const std::string& source,
                std::vector<uint8_t>& fixed) {
  const Points& X = cloud.positions;
  int selected = 0;
  auto fix = [&](Eigen::Index i) {
    fixed[i] = 1;
    ++selected;
  };
  switch (region.kind) {
    case FixedRegionKind::group: {
      if (cloud.mesh_tetrahedra == 0)
        throw SceneError(source, region.field + "/group",
                         "a group names a physical surface of a tetrahedral mesh; this body is not a mesh (use a "
                         "face name, a plane, a box or a sphere)");
      const NodeCloud::NodeSet* set = nullptr;
      std::string names;
      for (const NodeCloud::NodeSet& s : cloud.surface_node_sets) {
        if (s.name == region.group) set = &s;
        if (!s.name.empty()) names += (names.empty() ? "'" : ", '") + s.name + "'";
      }
      if (!set)
        throw SceneError(source, region.field + "/group",
                         "the mesh has no physical surface group named '" + region.group + "' (it has: " +
                             (names.empty() ? std::string("none") : names) + ")");
      for (int i : set->nodes) fix(i);
      break;
    }
    case FixedRegionKind::plane:
      for (Eigen::Index i = 0; i < X.cols(); ++i)
        if (std::abs(region.normal.dot(X.col(i) - region.point)) <= region.tolerance) fix(i);
      break;
    case FixedRegionKind::box:
      for (Eigen::Index i = 0; i < X.cols(); ++i)
        if ((X.col(i).array() >= region.min.array()).all() && (X.col(i).array() <= region.max.array()).all()) fix(i);
      break;
    case FixedRegionKind::sphere:
      for (Eigen::Index i = 0; i < X.cols(); ++i)
        if ((X.col(i) - region.center).norm() <= region.radius) fix(i);
      break;
  }
  if (selected == 0)
    throw SceneError(source, region.field, "selects no particle of the body (check its position, size or tolerance)");
}

std::vector<uint8_t> fixed_particles(const Scene& scene, const NodeCloud& cloud) {
  std::vector<uint8_t> fixed = particles_on_faces(cloud.positions, scene.fixed_faces);
  for (const FixedRegion& region : scene.fixed_regions) fix_region(cloud, region, scene.source, fixed);
  return fixed;
}

}  // namespace palpate
