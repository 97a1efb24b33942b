// The sliding study (tools/sliding.h; docs/physics.md §4, "The sliding test") on a coarse
// cloud: the tool, free, pressed with a constant normal force and dragged across the
// middle of the top face by the virtual coupling. The contact is frictionless, so the
// mean tangential force over the (symmetric) window must fall with the speed toward zero
// (what is left is the body's mass-proportional damping, linear in v), and the depth as
// the tool crosses the middle must be the static indentation there (relax_to_rest on the
// vertical guide: no sliding, no coupling).
#include <gtest/gtest.h>

#include "analysis/reference.h"
#include "core/model.h"
#include "core/options.h"
#include "test_util.h"
#include "tools/sliding.h"

namespace palpate {
namespace {

TEST(Sliding, TangentialForceVanishesInTheQuasiStaticLimitAndTheDepthIsStatic) {
  // 8^3 MLS (the default scene's model), symplectic Euler at 1 ms, damping 10 1/s.
  Scene scene = test::scene_from_json(R"({"body": {"distribution": {"type": "grid", "per_edge": 8}},
      "integrator": {"type": "symplectic_euler", "dt": 0.001, "damping": 10}})");
  SlideSpec spec;  // F = 82.88 N, middle (0, 0), window +-0.1 m, run-in 0.05 m, k = 1e4 N/m
  const Eigen::Vector2d start = slide_start(spec);
  place_indenter_at_site(scene, start[0], start[1]);
  const Model model = build_model(scene);
  const Options opt = options_of(scene);
  const StaticDepth truth = static_depth_at_middle(model, opt, scene.verify.rest, spec);
  ASSERT_TRUE(truth.converged) << truth.message;

  std::vector<SlideResult> rows;
  for (double v : {1.0, 0.1, 0.01}) {
    SlideSpec s = spec;
    s.speed = v;
    rows.push_back(slide(model, opt, scene.verify.rest, s));
    ASSERT_EQ(rows.back().status, "ok") << v << " m/s";
    // The normal load is the command: the mean contact force balances it.
    if (v <= 0.1) {
      EXPECT_NEAR(rows.back().mean_fz, spec.force, 2e-3 * spec.force) << v << " m/s";
    }
  }
  // Measured: |F_x| / |F_z| = 0.184, 0.0652, 0.00746 (and 7.6e-4 at 1 mm/s, 7.6e-5 at
  // 0.1 mm/s: linear in v), while the lattice's corrugation (rms F_x / F_z ~ 0.16) stays.
  EXPECT_GT(rows[0].ratio, rows[1].ratio);
  EXPECT_GT(rows[1].ratio, rows[2].ratio);
  EXPECT_LT(rows[2].ratio, 0.2 * rows[1].ratio);  // linear in v below 0.1 m/s: a factor 10 per decade
  EXPECT_LT(rows[2].ratio, 0.01);
  EXPECT_LT(rows[2].max_offset_y, 1e-6);  // the coupling holds the path's y
  // The depth at the middle: 0.0537159 m at 0.01 m/s against 0.0537138 static (+0.004 %).
  EXPECT_NEAR(rows[2].depth_middle, truth.depth, 2e-4 * truth.depth);
  EXPECT_GT(std::abs(rows[0].depth_middle - truth.depth), 0.05 * truth.depth);  // 1 m/s is not quasi-static
}

}  // namespace
}  // namespace palpate
