#include "server/local_model.h"

#include <Eigen/LU>

namespace palpate::server {

LocalModel render_model(const LocalModel& contact, bool position_mode, const Vec3& target,
                        const Vec3& render_force, const CouplingOptions& coupling) {
  if (!position_mode) return contact;
  LocalModel r = contact;
  r.origin = target;
  r.force = render_force;
  const double k = coupling.stiffness;
  // (P.1); k I - K_c is positive definite for k > 0 and K_c negative semi-definite.
  const Mat3 series = (k * Mat3::Identity() - contact.stiffness).inverse();
  r.stiffness = k > 0.0 ? Mat3(k * series * contact.stiffness) : Mat3::Zero();
  return r;
}

}  // namespace palpate::server
