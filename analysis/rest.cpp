#include "analysis/rest.h"

#include <algorithm>
#include <cmath>

namespace palpate {

double max_particle_speed(const State& state) { return std::sqrt(state.velocity.colwise().squaredNorm().maxCoeff()); }

void RestMonitor::start_window(const State& state) {
  window_start_position_ = state.position;
  window_start_indenter_ = state.indenter_center;
  held_ = 0.0;
}

PressResult press_to_rest(const Model& model, const Options& opt, const RestSpec& rest, State& state, double force) {
  return press_to_rest(model, opt, rest, state, force, [](const State&) {});
}

bool RestMonitor::update(const State& state, const Options& opt) {
  const double dt = opt.integrator.dt;
  const Vec3 axes = tool_axes(opt);
  const double imbalance = (state.indenter_contact_force + state.force_command).cwiseProduct(axes).norm();
  if (imbalance > spec_.force_tolerance * std::max(state.force_command.cwiseProduct(axes).norm(), 1e-12)) {
    held_ = -1.0;
    return false;
  }
  if (held_ < 0.0) {
    start_window(state);
    return false;
  }
  held_ += dt;
  if (held_ < spec_.window - 0.5 * dt) return false;
  const double allowed = spec_.velocity_tolerance * held_;
  const bool still = (state.indenter_center - window_start_indenter_).norm() <= allowed &&
                     (state.position - window_start_position_).colwise().norm().maxCoeff() <= allowed;
  if (still) return true;
  start_window(state);  // moved too much: judge the next window
  return false;
}

}  // namespace palpate
