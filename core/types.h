#pragma once
// Basic numeric types shared by every stage. SI units throughout (m, kg, s, N, Pa).
#include <Eigen/Core>

namespace palpate {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
// A set of points or per-particle 3-vectors: column i belongs to particle i
// (x, y, z contiguous per particle).
using Points = Eigen::Matrix<double, 3, Eigen::Dynamic>;

}  // namespace palpate
