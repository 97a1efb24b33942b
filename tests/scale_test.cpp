// Scenes at the scale of a hand (issue #13): a 10 cm tissue block pressed by a 1 cm, 5 g
// fingertip with the forces of a desktop haptic device (0.05 ... 3 N), lifted off and
// pressed again elsewhere, with every health check on; and the same scenario scaled by
// a factor 100 in length. Dimensional analysis is the independent truth for "the limits
// scale with the scene": with lengths x s, times x s, forces x s^2 and masses x s^3 (the
// same material, so stresses and wave speeds are unchanged) every dimensionless answer
// (d / R, c / L, F / (E R^2)) must be the same, and no limit may trip at one scale and
// not at the other.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <filesystem>
#include <optional>

#include "analysis/reference.h"
#include "analysis/rest.h"
#include "core/health.h"
#include "core/indentation.h"
#include "core/model.h"
#include "core/options.h"
#include "core/state.h"
#include "core/step.h"
#include "test_util.h"

namespace palpate {
namespace {

// A coarse palpation block (a 21 x 21 x 11 lattice, spacing 5 mm at s = 1), its length
// scale multiplied by s: box, spacing, radius and workspace x s, tool mass x s^3, dt x s,
// damping / s. E, nu and rho are the same at every scale.
std::string hand_block(double s) {
  const auto n = [](double v) {  // every digit: the two scales must differ by s alone
    char text[32];
    std::snprintf(text, sizeof text, "%.17g", v);
    return std::string(text);
  };
  return R"({"body": {"box": {"min": [)" + n(-0.05 * s) + "," + n(-0.05 * s) + "," + n(-0.05 * s) + R"(],
                              "max": [)" + n(0.05 * s) + "," + n(0.05 * s) + R"(, 0]},
                      "distribution": {"type": "grid", "spacing": )" + n(0.005 * s) + R"(}},
             "material": {"young_modulus": 5e4, "poisson_ratio": 0.3, "density": 8000, "volume_stiffness": 5e4,
                          "law": "corotational"},
             "fixed": ["bottom", "sides"],
             "indenter": {"radius": )" + n(0.01 * s) + R"(, "mass": )" + n(0.005 * s * s * s) + R"(, "guide": "free",
                          "workspace_min": [)" + n(-0.05 * s) + "," + n(-0.05 * s) + "," + n(-0.04 * s) + R"(],
                          "workspace_max": [)" + n(0.05 * s) + "," + n(0.05 * s) + "," + n(0.04 * s) + R"(]},
             "integrator": {"type": "symplectic_euler", "dt": )" + n(1e-3 * s) + R"(, "damping": )" + n(20.0 / s) + "}}";
}

// What a phase ends with, in units of the scene: lengths / (s R0), forces / s^2.
struct Snapshot {
  Vec3 center;        // tool centre / s, m at s = 1
  double depth = 0;   // indentation / s
  Vec3 contact;       // force of the body on the tool / s^2
  double speed = 0;   // |v| of the tool (invariant)
};

struct Palpation {
  std::vector<Snapshot> phases;
  std::vector<StepStatus> faults;  // every status other than ok, in order
  std::string first_fault;          // its report
  bool finite = true;
  bool at_workspace_top = false;   // after lift-off, on the box's top, still, out of contact
  double max_speed_in_flight = 0;  // the free tool's largest speed / its speed limit
};

// Press with 0.05 N, then `firm` N; lift off (3 N upward: the 5 g tool flies to the workspace
// top and stays there); move over another site and press it through the virtual coupling
// (a device position 3 mm below the surface at (2, 1) cm).
Palpation palpate(double s, double firm) {
  const test::Setup setup = test::setup_from_json(hand_block(s));
  const Model& model = setup.model;
  Options opt = setup.opt;
  State state = make_state(model, opt);
  Palpation run;
  const auto advance = [&](int steps, bool flight = false) {
    for (int k = 0; k < steps; ++k) {
      const StepStatus status = step(model, opt, state);
      if (status != StepStatus::ok) {
        if (run.faults.empty()) run.first_fault = describe(state.health.report) + " in phase " + std::to_string(run.phases.size());
        run.faults.push_back(status);
      }
      run.finite = run.finite && state.position.allFinite() && state.velocity.allFinite() &&
                   state.indenter_center.allFinite() && state.indenter_contact_force.allFinite();
      if (flight)
        run.max_speed_in_flight = std::max(run.max_speed_in_flight, state.indenter_velocity.norm() /
                                                                        health_limits(model, opt).max_indenter_speed);
    }
    run.phases.push_back({state.indenter_center / s, indentation(model, state) / s,
                          state.indenter_contact_force / (s * s), state.indenter_velocity.norm()});
  };
  state.force_command = press_down(0.05 * s * s);
  advance(300);
  state.force_command = press_down(firm * s * s);
  advance(300);
  state.force_command = press_down(-3.0 * s * s);
  advance(200, true);
  run.at_workspace_top = state.indenter_center.z() >= model.tool_workspace_max.z() - 1e-6 * s &&
                         state.contact_index.empty();
  state.force_command = Vec3::Zero();
  opt.coupling.stiffness = 50.0 * s;  // N/m: force x s^2 over length x s
  opt.coupling.damping = 1.0 * s * s;  // N s/m: about critical for the 5 g tool
  state.tool_target = Vec3(0.02, 0.01, -0.003) * s;
  advance(600);
  return run;
}

TEST(HandScale, PressLiftOffAndPressElsewhereWithoutAFault) {
  const Palpation run = palpate(1.0, 3.0);
  EXPECT_TRUE(run.finite);
  EXPECT_TRUE(run.faults.empty()) << run.faults.size() << " faults, the first " << run.first_fault;
  ASSERT_EQ(run.phases.size(), 4u);
  EXPECT_GT(run.phases[0].depth, 0.0);                        // 0.05 N presses in
  EXPECT_GT(run.phases[1].depth, 2 * run.phases[0].depth);   // 3 N presses much deeper
  EXPECT_TRUE(run.at_workspace_top);
  // Pressed again at the new site: in contact there, pulled toward the target.
  EXPECT_NEAR(run.phases[3].center.x(), 0.02, 2e-3);
  EXPECT_NEAR(run.phases[3].center.y(), 0.01, 2e-3);
  EXPECT_GT(run.phases[3].contact.z(), 0.0);
}

TEST(HandScale, ScaledByAHundredGivesTheSameDimensionlessAnswers) {
  // 0.5 N, not 3 N: under 3 N (d ~ R/2 on this coarse lattice) the free tool's lateral
  // balance is unstable, and round-off (1e-16 apart at the two scales) grows by about 1.2 per
  // 10 ms until the two runs part by per cents: chaos, not a scale dependence.
  const Palpation small = palpate(1.0, 0.5), large = palpate(100.0, 0.5);
  EXPECT_EQ(small.faults.size(), large.faults.size());
  EXPECT_EQ(small.at_workspace_top, large.at_workspace_top);
  ASSERT_EQ(small.phases.size(), large.phases.size());
  for (size_t p = 0; p < small.phases.size(); ++p) {
    SCOPED_TRACE("phase " + std::to_string(p));
    const Snapshot &a = small.phases[p], &b = large.phases[p];
    EXPECT_NEAR((b.center - a.center).norm(), 0.0, 1e-9 * 0.01);
    EXPECT_NEAR(b.depth, a.depth, 1e-6 * std::max(a.depth, 1e-4));
    EXPECT_NEAR((b.contact - a.contact).norm(), 0.0, 1e-6 * std::max(a.contact.norm(), 1e-3));
    EXPECT_NEAR(b.speed, a.speed, 1e-6 * std::max(a.speed, 1e-3));
  }
}

// The shipped palpation block (scenes/palpation_block.json: a 10 x 10 x 5 cm block, E = 20 kPa,
// R = 1 cm, a 5121-node tetrahedralisation fine at the centre of the top face, symplectic
// Euler at 1 ms) against its finite-block reference stored with the scenes, on the vertical
// guide of the Hertz experiment (a free frictionless tool under a vertical force has no
// lateral stiffness and wanders off the site): within 2 % at the ends and the middle of
// the sweep (d/R = 0.07 ... 0.2).
TEST(HandScale, PalpationBlockIsWithinTwoPercentOfItsFiniteBlockReference) {
  const std::filesystem::path dir = std::string(PALPATE_SOURCE_DIR) + "/scenes";
  const Scene scene = load_scene(dir / "palpation_block.json", {{"indenter.guide", "vertical"}});
  const std::optional<Reference> reference = find_reference(scene, dir / "references");
  ASSERT_TRUE(reference.has_value()) << "no stored reference for " << reference_key(scene);
  const Model model = build_model(scene);
  const Options opt = options_of(scene);
  State state = make_state(model, opt);
  for (double force : {scene.verify.forces.front(), scene.verify.forces[2], scene.verify.forces.back()}) {
    const PressResult r = press_to_rest(model, opt, scene.verify.rest, state, force);
    ASSERT_TRUE(r.at_rest) << "F = " << force;
    ASSERT_EQ(r.status, StepStatus::ok) << "F = " << force;
    const double d_ref = reference_indentation(*reference, force);
    EXPECT_NEAR(r.indentation / d_ref - 1.0, 0.0, 0.02) << "F = " << force << ", d = " << r.indentation;
  }
}

}  // namespace
}  // namespace palpate
