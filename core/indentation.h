#pragma once
// The indentation measure and rest detection (physics.md §2).
#include "core/model.h"
#include "core/scene.h"
#include "core/state.h"

namespace palpate {

// d = travel of the indenter centre below the height at which the sphere first
// touches the undeformed body (Model::touch_height), m. Positive when pressing.
double indentation(const Model& model, const State& state);

// Largest particle speed, m/s.
double max_particle_speed(const State& state);

// Equilibrium (physics.md §2): over a window of `window` seconds of simulated time
// the contact force balanced the command to force_tolerance (relative) at every
// step, and no particle and not the indenter moved more than
// velocity_tolerance * window (a mean speed below velocity_tolerance). Judging
// displacements rather than instantaneous speeds ignores the O(dt^3) velocity
// residue that RK4's free motion leaves on particles held by the contact projection.
class RestMonitor {
 public:
  explicit RestMonitor(const RestSpec& spec) : spec_(spec) {}
  // Call after every step; true once the criteria have held over a whole window.
  bool update(const Model& model, const State& state);
  void reset() { held_ = -1.0; }

 private:
  void start_window(const State& state);
  RestSpec spec_;
  double held_ = -1.0;  // s since the window started, < 0: no window open
  Points window_start_position_;
  double window_start_indenter_ = 0.0;
};

}  // namespace palpate
