#include "core/time_step.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "core/thread_pool.h"

namespace palpate {

double stability_constant(SolidKind solid, IntegratorType integrator, DistributionType distribution) {
  // c = dt_max c_p / dx_min measured at the Hertz load (palpate-stable-dt / palpate-stress,
  // bisection to 1-2 %, damping 10 1/s; docs/stability.md):
  //                           uniform 18^3   graded 21^3 (implicit: 11^3)
  //   MLS      RK4               1.51          2.07
  //   MLS      sympl. Euler      0.985         1.23
  //   MLS      implicit Euler    1.07          1.05
  //   hex FEM  RK4               1.48          1.58
  //   hex FEM  sympl. Euler      0.926         1.08
  //   hex FEM  implicit Euler    1.08          5.23
  // Implicit Euler is limited too: the indenter's motion is coupled to the body through
  // the contact solve, not inside the implicit system. Clouds other than these two
  // (jittered, node files, meshes) get the smaller constant.
  static constexpr double c[2][3][2] = {
      {{1.51, 2.07}, {0.985, 1.23}, {1.07, 1.05}},   // MLS: rk4, symplectic Euler, implicit Euler
      {{1.48, 1.58}, {0.926, 1.08}, {1.08, 5.23}}};  // hex FEM
  const auto& pair = c[solid == SolidKind::mls ? 0 : 1][static_cast<int>(integrator)];
  if (distribution == DistributionType::grid) return pair[0];
  if (distribution == DistributionType::graded_grid) return pair[1];
  return std::min(pair[0], pair[1]);
}

namespace {

// c_p with the volume term: sqrt((lambda + 2 mu + k_v) / rho), m/s, of the fastest material
// present (a heterogeneous body: the max over the particles' own parameters, so a stiff
// inclusion shrinks the stable dt).
double envelope_wave_speed(const Model& model) {
  double c2 = (model.lame_lambda + 2 * model.lame_mu + model.volume_stiffness) / model.density;
  if (model.particle_lambda.size() == static_cast<size_t>(model.particle_count) &&
      model.particle_mu.size() == model.particle_lambda.size() &&
      model.particle_density.size() == model.particle_lambda.size()) {
    c2 = 0.0;
    for (int i = 0; i < model.particle_count; ++i)
      c2 = std::max(c2, (model.particle_lambda[i] + 2 * model.particle_mu[i] + model.volume_stiffness) /
                            model.particle_density[i]);
  }
  return std::sqrt(c2);
}

double envelope_constant(const Model& model, IntegratorType integrator) {
  return stability_constant(model.solid, integrator, model.distribution);
}

}  // namespace

double stable_time_step(const Model& model, IntegratorType integrator) {
  return envelope_constant(model, integrator) * model.min_spacing / envelope_wave_speed(model);
}

void check_options(const Model& model, const Options& opt) {
  const IntegratorSpec& in = opt.integrator;
  if (in.threads < 1 || in.threads > kMaxThreads)
    throw SceneError(model.source, "/integrator/threads",
                     std::to_string(in.threads) + " threads (1 ... " + std::to_string(kMaxThreads) + ")");
  const double dt_max = stable_time_step(model, in.type);
  if (in.allow_unstable_dt || in.dt <= dt_max) return;
  char text[512];
  std::snprintf(text, sizeof text,
                "%g s is outside the measured stable envelope of %s with the %s model: dt <= c dx_min / c_p = "
                "%.3g x %.4g m / %.4g m/s = %.4g s (docs/stability.md). Use a smaller dt, or set "
                "integrator.allow_unstable_dt to true to run anyway",
                in.dt, to_string(in.type), to_string(model.solid), envelope_constant(model, in.type), model.min_spacing,
                envelope_wave_speed(model), dt_max);
  throw SceneError(model.source, "/integrator/dt", text);
}

}  // namespace palpate
