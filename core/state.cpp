#include "core/state.h"

#include "core/health.h"

namespace palpate {

State make_state(const Model& model, const Options& opt) {
  const int n = model.particle_count;
  State s;
  s.position = model.rest_position;
  s.velocity = Points::Zero(3, n);
  s.indenter_center = model.indenter_start;
  s.tool_target = model.indenter_start;
  s.force_command = press_down(model.initial_force_command);
  s.contact_index.reserve(n);
  s.contact_normal_force.reserve(n);
  s.contact_force.resize(3, n);
  s.out.contact_candidate.reserve(n);
  s.elastic_update_tick.assign(n, s.tick - 1);

  // Every integrator's scratch, so that Options::integrator may change between steps.
  Workspace& w = s.work;
  w.force.resize(3, n);
  for (int k = 0; k < 4; ++k) {
    w.rk_x[k].resize(3, n);
    w.rk_v[k].resize(3, n);
  }
  w.x0.resize(3, n);
  w.v0.resize(3, n);
  for (Points* p : {&w.cg_r, &w.cg_p, &w.cg_z, &w.cg_Ap, &w.rhs, &w.dv}) p->resize(3, n);
  w.tangent_F.resize(9 * static_cast<size_t>(n));
  w.tangent_law_factor.resize(9 * static_cast<size_t>(n));
  w.gap.reserve(n);
  w.normal.resize(3, n);
  w.candidate_slot.assign(n, -1);
  w.previous_multiplier.reserve(n);
  w.previous_force.resize(3, n);
  // Per-candidate vectors: room for every particle, never reallocated in the loop. The
  // dense m x m ones (implicit Euler's W~ and its factor): room for a few dozen contacts.
  const size_t all = static_cast<size_t>(n);
  for (std::vector<double>* v : {&w.multiplier, &w.delassus_diagonal, &w.delassus_product, &w.pivot_rhs}) v->reserve(all);
  w.delassus_factor.reserve(3 * all);
  w.active.reserve(all);
  w.members.reserve(all);
  w.guess.reserve(all);
  w.splitting.reserve(4 * all);
  w.subcycle_near.reserve(all);
  w.subcycle_extra.reserve(model.blocks.size());
  w.subcycle_blocks.reserve(model.blocks.size());
  w.subcycle_block_listed.assign(model.blocks.size(), 0);
  const size_t m = 64;
  w.delassus.reserve(m * m);
  w.solve_buffer.reserve(m * m);
  use_threads(model, opt, s);
  w.contact_response.resize(3, n);
  w.compliance.slot.assign(n, -1);
  reset_health(model, opt, s);
  return s;
}

void use_threads(const Model& model, const Options& opt, State& state) {
  WorkerThreads& t = state.work.threads;
  if (t.count() != opt.integrator.threads || t.particles != model.particle_count)
    t.resize(opt.integrator.threads, model.particle_count);
}

}  // namespace palpate
