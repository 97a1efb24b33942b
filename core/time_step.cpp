#include "core/time_step.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace palpate {

double stability_constant(SolidKind solid, IntegratorType integrator) {
  // Measured at the Hertz load (palpate-stable-dt, 1 % bisection tolerance), c = dt_max c_p / dx_min:
  //                      uniform 18^3   graded 21^3
  //   MLS      RK4          1.51          2.07
  //   MLS      sympl. Euler 0.985         1.23
  //   hex FEM  RK4          1.48          1.58
  //   hex FEM  sympl. Euler 0.926         1.08
  const bool mls = solid == SolidKind::mls;
  switch (integrator) {
    case IntegratorType::rk4: return mls ? 1.51 : 1.48;
    case IntegratorType::symplectic_euler: return mls ? 0.985 : 0.926;
    case IntegratorType::implicit_euler: return 0.0;
  }
  return 0.0;
}

double stable_time_step(const Model& model) {
  const double c = stability_constant(model.solid, model.scene.integrator.type);
  if (c == 0.0) return INFINITY;
  const double wave_speed =
      std::sqrt((model.lame_lambda + 2 * model.lame_mu + model.volume_stiffness) / model.scene.material.density);
  return c * model.min_spacing / wave_speed;
}

void check_time_step(const Model& model) {
  const IntegratorSpec& in = model.scene.integrator;
  const double dt_max = stable_time_step(model);
  if (in.allow_unstable_dt || in.dt <= dt_max) return;
  char text[512];
  std::snprintf(text, sizeof text,
                "%g s is outside the measured stable envelope of %s with the %s model: dt <= c dx_min / c_p = "
                "%.3g x %.4g m / %.4g m/s = %.4g s (docs/stability.md). Use a smaller dt, implicit_euler, or set "
                "integrator.allow_unstable_dt to true to run anyway",
                in.dt, to_string(in.type), model.scene.model.c_str(),
                stability_constant(model.solid, in.type), model.min_spacing,
                model.min_spacing * stability_constant(model.solid, in.type) / dt_max, dt_max);
  throw SceneError(model.scene.source, "/integrator/dt", text);
}

}  // namespace palpate
