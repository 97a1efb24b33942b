#pragma once
// The force a frame's local contact model gives at a point, docs/protocol.md (P.0): the one
// formula the server's multirate renderer (server/haptic_loop.cpp) and the clients
// (clients/haptic.cpp) render with, so that what the server streams and what a client
// renders between frames cannot drift apart.
//
//   F(x) = F0 + K (x - x0),  x - x0 clipped to |x - x0| <= valid_radius,
//
// with K applied only when valid_radius > 0 and a stiffness was computed (otherwise the
// zero-order hold F0), then saturated at max_force (> 0; 0 = no limit) by scaling the
// vector to that length. Plain arrays: the server holds Eigen vectors, the clients
// std::array; both pass their data.
#include <cmath>

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

}  // namespace palpate::protocol
