// The spectral stable step (core/time_step.h, spectral_time_step) against the dynamics it
// predicts: symplectic Euler on the free body (the tool lifted off, no damping, no health
// checks), started from a small seeded velocity that has a part in every mode, stays bounded
// below the predicted step and blows up above it. An independent truth: the step's own
// arithmetic, not the eigenvalue estimate, decides.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/step.h"
#include "core/time_step.h"

namespace palpate {
namespace {

namespace fs = std::filesystem;

double kinetic(const Model& m, const State& s) {
  double e = 0;
  for (int i = 0; i < m.particle_count; ++i) e += 0.5 * m.mass[i] * s.velocity.col(i).squaredNorm();
  return e;
}

// The largest kinetic energy over `steps` steps relative to the start (inf when it overflows).
double growth(const Model& model, Options opt, double dt, int steps) {
  opt.integrator.dt = dt;
  opt.integrator.damping = 0.0;
  opt.integrator.allow_unstable_dt = true;
  opt.integrator.max_interval = 1;  // one rate: the spectral estimate's
  opt.health.enabled = false;
  State state = make_state(model, opt);
  state.indenter_center[2] += 0.05;  // well off the body: no contact
  state.tool_target = state.indenter_center;
  std::mt19937_64 rng(7);
  for (int i = 0; i < model.particle_count; ++i)
    if (!model.fixed[i])
      for (int c = 0; c < 3; ++c) state.velocity(c, i) = 1e-6 * (static_cast<double>(rng() >> 11) * 0x1.0p-53 - 0.5);
  const double e0 = kinetic(model, state);
  double worst = 1.0;
  for (int k = 0; k < steps; ++k) {
    step(model, opt, state);
    const double e = kinetic(model, state);
    if (!std::isfinite(e)) return INFINITY;
    worst = std::max(worst, e / e0);
  }
  return worst;
}

TEST(SpectralTimeStep, SeparatesStableFromUnstableSteps) {
  // One rate: a subcycled model's blocks are regrouped after the estimate (core/rate_schedule.h),
  // and the estimate is compared bit for bit below.
  Scene scene = load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_block_follow.json",
                           {{"integrator.max_interval", "1"}});
  scene.indenter.position_given = true;
  scene.indenter.position = Vec3(-0.015, 0.0, 0.0101);  // a site with a close pair (0.23 mm)
  const Model model = build_model(scene);
  const Options opt = options_of(scene);
  const double dt = spectral_time_step(model, IntegratorType::symplectic_euler);
  ASSERT_GT(dt, 0.0);
  // The spacing estimate misjudges this cloud by more than three times (0.43 against 1.46 ms).
  EXPECT_GT(dt, 2 * stable_time_step(model, IntegratorType::symplectic_euler));
  // Measured (density 8e4): 0.98 x the spectral step bounded (energy x 1), 1.02 x it overflows
  // within 600 steps.
  EXPECT_LT(growth(model, opt, 0.97 * dt, 500), 10.0);
  EXPECT_GT(growth(model, opt, 1.03 * dt, 500), 1e6);
  // build_model keeps it when the scene's dt needs it (this scene's 1 ms does), and
  // check_options then accepts kSpectralSafety of it, no more; a dt the spacing estimate
  // accepts does not compute it.
  EXPECT_DOUBLE_EQ(model.spectral_time_step, dt);
  Options fast = opt;
  fast.integrator.dt = 1.01 * kSpectralSafety * dt;
  EXPECT_THROW(check_options(model, fast), SceneError);
  fast.integrator.dt = 0.99 * kSpectralSafety * dt;
  EXPECT_NO_THROW(check_options(model, fast));
  scene.integrator.dt = 0.9 * stable_time_step(model, IntegratorType::symplectic_euler);
  EXPECT_EQ(build_model(scene).spectral_time_step, 0.0);
}

}  // namespace
}  // namespace palpate
