#include "tools/sliding.h"

#include <chrono>
#include <cmath>

#include "analysis/reference.h"
#include "analysis/rest.h"
#include "analysis/static_contact.h"
#include "core/checkpoint.h"
#include "core/health.h"
#include "core/state.h"
#include "core/step.h"

namespace palpate {

Eigen::Vector2d slide_start(const SlideSpec& spec) {
  return Eigen::Vector2d(spec.middle[0] - spec.half_window - spec.run_in, spec.middle[1]);
}

SlideResult slide(const Model& model, const Options& opt, const RestSpec& rest, const SlideSpec& spec) {
  const auto start = std::chrono::steady_clock::now();
  SlideResult out;
  out.speed = spec.speed;
  State state = make_state(model, opt);

  // 1. At rest under the normal force at the start of the path, on the vertical guide.
  Options guided = opt;
  guided.tool_guide = ToolGuide::vertical;
  guided.coupling = {};
  const PressResult press = press_to_rest(model, guided, rest, state, spec.force);
  out.press_steps = press.steps;
  if (press.failure.status != StepStatus::ok) {
    out.status = "diverged: " + describe(press.failure);
    return out;
  }
  if (!press.at_rest) out.status = "not at rest";

  // 2. Free tool, coupling on: the target moves along x at v, holds y_m, and its z
  //    follows the tool (the spring pulls sideways only; the normal load is the command).
  Options sliding = opt;
  sliding.tool_guide = ToolGuide::free;
  sliding.coupling.stiffness = spec.stiffness;
  sliding.coupling.damping = spec.damping >= 0 ? spec.damping : 2.0 * std::sqrt(spec.stiffness * opt.indenter_mass);
  reset_health(model, sliding, state);
  const double x0 = state.indenter_center[0], y_m = spec.middle[1];
  const double x_lo = spec.middle[0] - spec.half_window, x_hi = spec.middle[0] + spec.half_window;
  const double dt = opt.integrator.dt;
  const double t0 = state.time;
  // Generous: the tool lags the target by (b v + F_x) / k; the loop ends when it leaves the window.
  const long max_steps = static_cast<long>(std::ceil((x_hi - x0 + 0.05 + 2 * sliding.coupling.damping * spec.speed / spec.stiffness) /
                                                     (spec.speed * dt))) + 1000;
  double sum_fx = 0, sum_fz = 0, sum_fx2 = 0;
  long samples = 0;
  double prev_x = state.indenter_center[0], prev_d = indentation_at_tool(model, state),
         prev_lag = state.tool_target[0] - prev_x;
  Checkpoint last_good(state);
  for (long k = 0; k < max_steps; ++k) {
    state.tool_target = Vec3(x0 + spec.speed * (state.time - t0 + dt), y_m, state.indenter_center[2]);  // (4.3)
    const StepStatus status = step(model, sliding, state);
    ++out.steps;
    if (is_fault(status)) {
      out.status = "diverged: " + describe(state.health.report);
      last_good.restore(state);
      break;
    }
    if (k % 100 == 0) last_good.save(state);
    const Vec3& c = state.indenter_center;
    if (c[0] >= x_lo && c[0] <= x_hi) {
      const Vec3& f = state.indenter_contact_force;
      sum_fx += f[0];
      sum_fz += f[2];
      sum_fx2 += f[0] * f[0];
      ++samples;
      out.max_offset_y = std::max(out.max_offset_y, std::abs(c[1] - y_m));
    }
    if (prev_x < spec.middle[0] && c[0] >= spec.middle[0]) {  // crossing the middle: interpolate in c_x
      const double d = indentation_at_tool(model, state), lag = state.tool_target[0] - c[0];
      const double s = (spec.middle[0] - prev_x) / (c[0] - prev_x);
      out.depth_middle = prev_d + s * (d - prev_d);
      out.lag = prev_lag + s * (lag - prev_lag);
    }
    if (c[0] > x_hi) break;
    prev_x = c[0];
    prev_d = prev_x >= x_lo - 0.01 ? indentation_at_tool(model, state) : NAN;  // only near the middle: O(n)
    prev_lag = state.tool_target[0] - c[0];
  }
  out.sim_time = state.time - t0;
  if (samples > 0) {
    out.mean_fx = sum_fx / samples;
    out.mean_fz = sum_fz / samples;
    out.ratio = std::abs(out.mean_fx) / std::abs(out.mean_fz);                   // (4.4)
    out.rms_ratio = std::sqrt(sum_fx2 / samples) / std::abs(out.mean_fz);
  }
  if (out.status == "ok" && !(state.indenter_center[0] > x_hi)) out.status = "did not cross the window";
  out.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

StaticDepth static_depth_at_middle(const Model& model, const Options& opt, const RestSpec& rest,
                                   const SlideSpec& spec) {
  StaticDepth out;
  Options guided = opt;
  guided.tool_guide = ToolGuide::vertical;
  guided.coupling = {};
  State state = make_state(model, guided);
  // The sphere over the middle, just touching the undeformed body (as a verification run starts).
  state.indenter_center =
      Vec3(spec.middle[0], spec.middle[1],
           first_contact_height(model.rest_position, model.indenter_radius, spec.middle[0], spec.middle[1]));
  state.tool_target = state.indenter_center;
  reset_health(model, guided, state);
  const StaticSolution sol = relax_to_rest(model, guided, rest, state, spec.force);
  out.converged = sol.converged;
  out.message = sol.message;
  out.depth = indentation_at_tool(model, state);
  return out;
}

}  // namespace palpate
