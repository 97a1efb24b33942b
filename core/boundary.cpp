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

}  // namespace palpate
