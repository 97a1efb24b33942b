#pragma once
// The multirate verification (issue #17, docs/verification.md "Multirate haptics"):
// the force a device gets along the palpation path when the full model steps at a
// coarse rate and the server renders the force at the haptic rate from the newest
// step's local model (server/haptic_loop.h, render_sample), against the truth of the
// same scene stepped at the haptic rate (every tick a full step, the device's position
// applied at once), and against the zero-order hold of the coarse steps' forces (what
// a client without the local model renders).
//
// Both runs are headless sessions of the server's own session thread
// (server/sim_loop.h), deterministic. The coarse step j (state at time (j + 1) Δ,
// device position taken at j Δ) is rendered from at the haptic ticks at times >= (j + 1) Δ
// only: as if every step took its whole period (the real server publishes sooner, so
// this is the pessimistic case).
#include <cstddef>
#include <string>
#include <vector>

#include "clients/haptic.h"
#include "core/scene.h"
#include "core/types.h"
#include "server/sim_loop.h"

namespace palpate::bench {

// A headless session of the server's session thread, in process, stepped one tick at a
// time with the device at a position (position mode). Throws std::runtime_error with the
// session's message when it fails to start or blows up.
class HeadlessSession {
 public:
  // contact_stiffness: compute the frames' local models (at every step: costly on fine clouds).
  // touch_lookahead: SimConfig::touch_lookahead (s).
  HeadlessSession(Scene scene, bool contact_stiffness, double touch_lookahead = 0.0);
  // One tick with the device at x; the frame it published.
  const server::Snapshot& step(const Vec3& x);
  const Model& model() const { return sim_.shown_model(); }
  CouplingOptions coupling() const { return sim_.initial_coupling(); }
  double seconds() const { return seconds_; }  // wall time spent stepping

 private:
  static server::SimConfig config(bool contact_stiffness, double touch_lookahead);
  void wait();
  server::Simulation sim_;
  double seconds_ = 0;
};

struct MultirateConfig {
  std::string scene_file;
  SceneOverrides overrides;     // applied to both runs (indenter.guide=free is added unless given)
  double haptic_rate_hz = 1000;  // the render rate, and the truth's step rate
  double model_dt = 0;           // s, the coarse step; 0: the scene's integrator.dt
  double seconds = 6;            // the path's duration
  double depth = 0;              // m below first touch; 0: R / 5
  // Also render with the contact stiffness of N coarse steps before the step rendered
  // from, for each N here (origin and force stay the newest step's): a real-time
  // session's stiffness worker lags the loop (palpate-bench-haptic's "stiffness age").
  // MultirateSample::lagged, in this order.
  std::vector<int> stiffness_lags;
  // The coarse run's stiffness at first touch is taken this far ahead (s, docs/physics.md
  // (2.22)); 0: at the touch.
  double touch_lookahead = 0.0;
};

struct MultirateSample {
  double t;            // s, the render tick's time
  size_t segment;      // index into MultirateResult::segments
  Vec3 truth;          // N, the render force of the run stepped at the haptic rate
  Vec3 multirate;      // N, rendered from the newest coarse step's local model
  Vec3 hold;           // N, the newest coarse step's own render force (zero-order hold)
  std::vector<Vec3> lagged;  // N, as multirate with the stiffness MultirateConfig::stiffness_lags older
  double model_age;    // s, render time minus the coarse step's state time
};

struct MultirateResult {
  std::vector<haptic::PalpationPath::Segment> segments;
  std::vector<MultirateSample> samples;
  int particles = 0;
  double model_dt = 0, haptic_dt = 0;  // s
  double truth_seconds = 0, coarse_seconds = 0;  // wall time of the two runs' stepping
  double peak = 0;  // N, the largest |truth|
};

// Throws std::runtime_error (the scene's or a session's message) when a run fails.
MultirateResult run_multirate_study(const MultirateConfig& config);

}  // namespace palpate::bench
