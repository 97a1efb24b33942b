#include "core/state.h"

#include "core/health.h"

namespace palpate {

State make_state(const Model& model) {
  const int n = model.particle_count;
  State s;
  s.position = model.rest_position;
  s.velocity = Points::Zero(3, n);
  s.indenter_center = model.indenter_start;
  s.force_command = model.scene.indenter.force;
  s.contact_index.reserve(n);
  s.contact_multiplier.reserve(n);
  s.contact_force.resize(3, n);

  Workspace& w = s.work;
  w.force.resize(3, n);
  w.candidate.reserve(n);
  w.gap.reserve(n);
  w.normal.resize(3, n);
  w.candidate_slot.assign(n, -1);
  w.previous_multiplier.reserve(n);
  w.previous_force.resize(3, n);
  switch (model.scene.integrator.type) {
    case IntegratorType::rk4:
      for (int k = 0; k < 4; ++k) {
        w.rk_x[k].resize(3, n);
        w.rk_v[k].resize(3, n);
      }
      w.x0.resize(3, n);
      w.v0.resize(3, n);
      break;
    case IntegratorType::symplectic_euler:
      w.rk_v[0].resize(3, n);
      break;
    case IntegratorType::implicit_euler:
      for (Points* p : {&w.cg_r, &w.cg_p, &w.cg_z, &w.cg_Ap, &w.rhs, &w.dv}) p->resize(3, n);
      w.cached_F.resize(9 * static_cast<size_t>(n));
      w.cached_S.resize(9 * static_cast<size_t>(n));
      break;
  }
  // Room for a few dozen contacts without reallocation in the loop.
  const size_t m = 64;
  w.delassus.reserve(m * m);
  w.multiplier.reserve(m);
  w.solve_buffer.reserve(m * m + m);
  w.active.reserve(m);
  w.members.reserve(m);
  reset_health(model, s);
  return s;
}

}  // namespace palpate
