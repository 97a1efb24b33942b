#pragma once
// The local contact model of a frame (wire LocalModel, docs/protocol.md "The local contact
// model"), decoded, and the force it gives at a point, docs/protocol.md (P.0): the one
// definition the server (which computes the models, server/local_model.h, and renders them in
// its multirate renderer, server/haptic_loop.cpp) and the clients (which render them between
// frames, clients/haptic.h) share, so that what the server streams and what a client renders
// cannot drift apart.
//
//   F(x) = F0 + K (x - x0),  x - x0 clipped to |x - x0| <= valid_radius,
//
// with K applied only when valid_radius > 0 and a stiffness was computed (otherwise the
// zero-order hold F0), then saturated at max_force (> 0; 0 = no limit) by scaling the
// vector to that length.
//
// The struct is written once over its user's vector and matrix types: the server computes
// with Eigen (server/snapshot.h: LocalModel<Vec3, Mat3>), the clients, which have no Eigen,
// hold std::array (clients/haptic.h: LocalModel<std::array<double, 3>, std::array<double, 9>>,
// the matrix row-major as on the wire). The formula itself works on plain arrays
// (local_model_force), for a program that keeps the wire's numbers its own way.
#include <cmath>
#include <cstdint>

namespace palpate::protocol {

// Scales f (3) to max_force when it is longer (max_force > 0); true if it did.
inline bool saturate_force(double* f, double max_force) {
  const double length = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
  if (!(max_force > 0.0 && length > max_force)) return false;
  const double scale = max_force / length;
  for (int i = 0; i < 3; ++i) f[i] *= scale;
  return true;
}

// out (3) = F(x) above; origin, force and x: 3 doubles, m and N; stiffness: 9, N/m,
// row-major (stiffness[3 i + j] = dF_i / dx_j); has_stiffness: the model's stiffness_tick
// >= 0. Returns whether the force was saturated.
inline bool local_model_force(const double* origin, const double* force, const double* stiffness,
                              double valid_radius, bool has_stiffness, const double* x, double max_force,
                              double* out) {
  for (int i = 0; i < 3; ++i) out[i] = force[i];
  if (valid_radius > 0.0 && has_stiffness) {
    double d[3] = {x[0] - origin[0], x[1] - origin[1], x[2] - origin[2]};
    const double length = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (length > valid_radius) {
      const double scale = valid_radius / length;
      for (double& c : d) c *= scale;
    }
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) out[i] += stiffness[3 * i + j] * d[j];
  }
  return saturate_force(out, max_force);
}

// A zero of T: T::Zero() (Eigen), else a value-initialised T (std::array: all zeros).
template <class T>
T zero_value() {
  if constexpr (requires { T::Zero(); })
    return T::Zero();
  else
    return T{};
}

// Vector: 3 doubles with data() (Eigen::Vector3d, std::array<double, 3>). Matrix: 3 x 3
// doubles, either with m(i, j) (Eigen::Matrix3d, any storage order) or 9 contiguous ones
// row-major with data() (std::array<double, 9>).
template <class Vector, class Matrix>
struct LocalModel {
  Vector origin = zero_value<Vector>();     // m
  Vector force = zero_value<Vector>();      // N, at origin
  Matrix stiffness = zero_value<Matrix>();  // N/m, dF/dx
  double valid_radius = 0.0;                // m; 0 = do not extrapolate
  int64_t stiffness_tick = -1;              // tick of the state the stiffness comes from (-1: none yet, K = 0)

  // F(x) (P.0) at x, saturated at max_force (> 0; 0 = no limit); `saturated` (optional)
  // says whether it was.
  Vector force_at(const Vector& x, double max_force, bool* saturated = nullptr) const {
    Vector f;
    bool clipped;
    if constexpr (requires { stiffness(0, 0); }) {
      double k[9];  // row-major
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) k[3 * i + j] = stiffness(i, j);
      clipped = local_model_force(origin.data(), force.data(), k, valid_radius, stiffness_tick >= 0, x.data(),
                                  max_force, f.data());
    } else {
      clipped = local_model_force(origin.data(), force.data(), stiffness.data(), valid_radius, stiffness_tick >= 0,
                                  x.data(), max_force, f.data());
    }
    if (saturated != nullptr) *saturated = clipped;
    return f;
  }
};

}  // namespace palpate::protocol
