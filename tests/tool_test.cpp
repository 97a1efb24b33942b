// The tool as a rigid sphere with three translations (issue #13, first part): a free
// tool exchanges momentum with a free body exactly (the contact projections are
// M-metric: a conservation law, independent of the solver), a vertical guide holds the
// lateral position, the workspace keeps a pulled-away tool in reach (lift-off is a
// normal state, not a fault), and the scene fields are validated.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "core/health.h"
#include "core/indentation.h"
#include "core/state.h"
#include "core/step.h"
#include "test_util.h"

namespace palpate {
namespace {

// A free 6^3 lattice cube of 1 m (no fixed faces, no gravity, no damping) and a tool of
// radius 0.2 m beside it.
std::string free_body(const std::string& indenter) {
  return R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}, "distribution": {"type": "grid", "per_edge": 6}},
             "mls": {"neighbors": 18, "support_factor": 1.05, "support_rule": "kth_distance", "volumes": "lattice"},
             "material": {"young_modulus": 2000, "poisson_ratio": 0.3, "density": 1000},
             "fixed": [],
             "indenter": )" + indenter + R"(,
             "integrator": {"type": "symplectic_euler", "dt": 0.001}})";
}

Vec3 momentum(const Model& m, const Options& opt, const State& s) {
  Vec3 p = opt.indenter_mass * s.indenter_velocity;
  for (int i = 0; i < m.particle_count; ++i) p += m.mass[i] * s.velocity.col(i);
  return p;
}

TEST(Tool, FreeToolAndFreeBodyConserveMomentumThroughContact) {
  // The tool comes in diagonally from above one top corner region and hits the body.
  const test::Setup setup = test::setup_from_json(free_body(
      R"({"radius": 0.2, "mass": 50, "position": [0.3, 0.4, 1.25], "guide": "free",
          "workspace_min": [-10, -10, -10], "workspace_max": [10, 10, 10]})"));
  const Model& m = setup.model;
  const Options& opt = setup.opt;
  State s = make_state(m, opt);
  s.indenter_velocity = Vec3(0.4, -0.3, -1.0);
  reset_health(m, opt, s);
  const Vec3 p0 = momentum(m, opt, s);
  size_t most_contacts = 0;
  double scale = p0.norm();
  for (int k = 0; k < 400; ++k) {
    ASSERT_EQ(step(m, opt, s), StepStatus::ok) << "step " << k << ": " << describe(s.health.report);
    most_contacts = std::max(most_contacts, s.contact_index.size());
    const Vec3 p = momentum(m, opt, s);
    ASSERT_LT((p - p0).norm(), 1e-10 * scale) << "step " << k;
  }
  EXPECT_GT(most_contacts, 0u);  // it did hit
  // The body took momentum in all three directions: the tool's lateral motion was coupled.
  Vec3 body = Vec3::Zero();
  for (int i = 0; i < m.particle_count; ++i) body += m.mass[i] * s.velocity.col(i);
  EXPECT_GT(std::abs(body[0]), 1e-3 * scale);
  EXPECT_GT(std::abs(body[2]), 1e-3 * scale);
}

TEST(Tool, ContactForceOnTheToolIsTheSumOfTheNormalForces) {
  const test::Setup setup = test::setup_from_json(free_body(
      R"({"radius": 0.2, "mass": 5, "position": [0.35, 0.55, 1.2], "guide": "free", "force": 20,
          "workspace_min": [-10, -10, -10], "workspace_max": [10, 10, 10]})"));
  const Model& m = setup.model;
  const Options& opt = setup.opt;
  State s = make_state(m, opt);
  for (int k = 0; k < 300; ++k) ASSERT_EQ(step(m, opt, s), StepStatus::ok);
  ASSERT_GT(s.contact_index.size(), 0u);
  Vec3 on_body = Vec3::Zero();
  for (size_t c = 0; c < s.contact_index.size(); ++c) {
    const Vec3 f = s.contact_force.col(static_cast<Eigen::Index>(c));
    on_body += f;
    // Frictionless: each force is along the normal from the sphere's centre (taken at the
    // contact solve, before its projections moved particle and tool by O(dt^2 F / m)).
    const Vec3 n = (s.position.col(s.contact_index[c]) - s.indenter_center).normalized();
    EXPECT_LT((f - f.dot(n) * n).norm(), 1e-3 * f.norm());
    EXPECT_NEAR(f.norm(), s.contact_normal_force[c], 1e-9 * f.norm());
  }
  EXPECT_LT((s.indenter_contact_force + on_body).norm(), 1e-9 * on_body.norm());
}

TEST(Tool, VerticalGuideHoldsTheLateralPositionOffCentre) {
  // Pressed off-centre and near a wall of a fixed-bottom block, the vertical guide takes
  // the lateral force: the tool's x and y never change and its lateral velocity is zero,
  // while the contact force on it has a lateral part.
  const std::string scene = R"({"body": {"distribution": {"per_edge": 10}},
    "indenter": {"position": [0.6, 0.45, 0.6], "force": 100},
    "integrator": {"type": "symplectic_euler", "dt": 0.002, "damping": 10}})";
  const test::Setup setup = test::setup_from_json(scene);
  const Model& m = setup.model;
  const Options& opt = setup.opt;
  EXPECT_EQ(opt.tool_guide, ToolGuide::vertical);
  State s = make_state(m, opt);
  const Vec3 start = s.indenter_center;
  double lateral = 0;
  for (int k = 0; k < 1500; ++k) {
    ASSERT_EQ(step(m, opt, s), StepStatus::ok);
    ASSERT_EQ(s.indenter_center[0], start[0]);
    ASSERT_EQ(s.indenter_center[1], start[1]);
    ASSERT_EQ(s.indenter_velocity.head<2>().norm(), 0.0);
    lateral = std::max(lateral, s.indenter_contact_force.head<2>().norm());
  }
  EXPECT_GT(indentation(m, s), 0.0);
  EXPECT_GT(lateral, 1e-3);  // off-centre on a lattice the surface pushes sideways
}

TEST(Tool, PulledAwayToolStopsAtTheWorkspaceAndIsHealthy) {
  // 1e4 N pulling up a 1 kg tool: without the workspace this is 1e4 m/s^2 and a fault
  // within a few ticks; with it, lift-off ends at the workspace's top and every step is ok.
  const test::Setup setup = test::setup_from_json(R"({"body": {"distribution": {"per_edge": 8}},
    "indenter": {"force": -1e4}, "integrator": {"type": "symplectic_euler", "dt": 0.001, "damping": 10}})");
  const Model& m = setup.model;
  const Options& opt = setup.opt;
  State s = make_state(m, opt);
  EXPECT_NEAR(m.tool_workspace_max[2], m.rest_position.row(2).maxCoeff() + 2 * m.indenter_radius, 1e-12);
  for (int k = 0; k < 500; ++k) ASSERT_EQ(step(m, opt, s), StepStatus::ok) << describe(s.health.report);
  EXPECT_EQ(s.indenter_center[2], m.tool_workspace_max[2]);
  EXPECT_EQ(s.indenter_velocity[2], 0.0);
  EXPECT_TRUE(s.contact_index.empty());
  // Pressing again from up there brings it back into contact.
  s.force_command = press_down(50.0);
  for (int k = 0; k < 3000 && s.contact_index.empty(); ++k) ASSERT_EQ(step(m, opt, s), StepStatus::ok);
  EXPECT_FALSE(s.contact_index.empty());
}

// The virtual coupling is passive (docs/physics.md (2.6)): moving the device by dT does
// the work k (T - c) . dT + 1/2 k |dT|^2 on the spring (what its energy gains with c
// held), and the implicit step with T held can only lose energy. So the tool's energy
// 1/2 M |v|^2 + 1/2 k |T - c|^2 never exceeds the device's work, to round-off, even at a
// stiffness whose explicit step would be unstable (omega dt = 3.2).
TEST(Tool, VirtualCouplingNeverPutsInMoreThanTheDeviceWork) {
  const test::Setup setup = test::setup_from_json(free_body(
      R"({"radius": 0.05, "mass": 0.01, "position": [0.4, 0.4, 3], "guide": "free",
          "workspace_min": [-10, -10, -10], "workspace_max": [10, 10, 10]})"));
  const Model& m = setup.model;
  Options opt = setup.opt;
  opt.coupling.stiffness = 1e5;  // N/m: 100 N/mm
  opt.coupling.damping = 0.5;    // N s/m
  State s = make_state(m, opt);
  const Vec3 start = s.indenter_center;
  double device_work = 0.0, most = 0.0;
  auto tool_energy = [&] {
    return 0.5 * opt.indenter_mass * s.indenter_velocity.squaredNorm() +
           0.5 * opt.coupling.stiffness * (s.tool_target - s.indenter_center).squaredNorm();
  };
  for (int k = 0; k < 2000; ++k) {
    // A device path with corners: a square of 5 cm side at 1 m/s, then a jump.
    const double t = (k + 1) * opt.integrator.dt;
    const double u = std::fmod(t, 0.2) / 0.05;
    Vec3 target = start + (u < 1 ? Vec3(0.05 * u, 0, 0)
                          : u < 2 ? Vec3(0.05, 0.05 * (u - 1), 0)
                          : u < 3 ? Vec3(0.05 * (3 - u), 0.05, 0)
                                  : Vec3(0, 0.05 * (4 - u), 0));
    if (k == 1500) target += Vec3(0, 0, 0.02);
    const Vec3 dT = target - s.tool_target;
    device_work += opt.coupling.stiffness * (s.tool_target - s.indenter_center).dot(dT) +
                   0.5 * opt.coupling.stiffness * dT.squaredNorm();
    s.tool_target = target;
    ASSERT_EQ(step(m, opt, s), StepStatus::ok);
    most = std::max(most, tool_energy());
    ASSERT_LE(tool_energy(), device_work + 1e-12 * std::max(1.0, device_work)) << "step " << k;
  }
  EXPECT_GT(most, 1e-4);  // the spring was loaded
  // The coupling force reported is the spring-damper's on the tool.
  const Vec3 expected = opt.coupling.stiffness * (s.tool_target - s.indenter_center) -
                        opt.coupling.damping * s.indenter_velocity;
  EXPECT_LT((s.out.coupling_force - expected).norm(), 1e-9 * std::max(1.0, expected.norm()));
}

// A slowly moving device pressing into a fixed-bottom block: at rest the coupled tool
// lags its target by F/k, F the contact force (k (T - c) + F_c = 0), laterally too.
TEST(Tool, CoupledToolFollowsASlowTargetWithinForceOverStiffness) {
  const test::Setup setup = test::setup_from_json(R"({"body": {"distribution": {"per_edge": 10}},
    "indenter": {"radius": 0.5, "mass": 0.5, "guide": "free"},
    "integrator": {"type": "symplectic_euler", "dt": 0.002, "damping": 10}})");
  const Model& m = setup.model;
  Options opt = setup.opt;
  opt.coupling.stiffness = 2000;  // N/m
  opt.coupling.damping = 40;      // N s/m
  State s = make_state(m, opt);
  const Vec3 start = s.indenter_center;
  // 0.1 m down and 0.05 m sideways over 2 s, then held for 3 s.
  for (int k = 0; k < 2500; ++k) {
    const double f = std::min(1.0, (k + 1) * opt.integrator.dt / 2.0);
    s.tool_target = start + f * Vec3(0.05, 0.0, -0.1);
    ASSERT_EQ(step(m, opt, s), StepStatus::ok) << "step " << k << ": " << describe(s.health.report);
  }
  const Vec3 lag = s.tool_target - s.indenter_center;
  const Vec3 contact = s.indenter_contact_force;
  EXPECT_GT(contact[2], 10.0);  // pressed in
  EXPECT_LT((opt.coupling.stiffness * lag + contact).norm(), 1e-3 * contact.norm());
  EXPECT_NEAR(lag.norm(), contact.norm() / opt.coupling.stiffness, 1e-3 * lag.norm());
  EXPECT_NEAR(s.indenter_center[0], s.tool_target[0] + contact[0] / opt.coupling.stiffness, 1e-4);
}

TEST(Tool, WorkspaceAndGuideFieldsAreValidated) {
  EXPECT_THROW(test::scene_from_json(R"({"indenter": {"guide": "sideways"}})"), SceneError);
  EXPECT_THROW(test::scene_from_json(R"({"indenter": {"workspace_min": [0, 0, 0], "workspace_max": [1, 0, 1]}})"),
               SceneError);
  EXPECT_THROW(test::scene_from_json(R"({"indenter": {"workspace_min": [0, 0]}})"), SceneError);
  // A start outside a given workspace is refused at the build, naming the field.
  try {
    test::model_from_json(R"({"indenter": {"workspace_min": [-3, -3, 1], "workspace_max": [3, 3, 4]}})");
    ADD_FAILURE() << "a tool starting below its workspace was accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/indenter/workspace_min");
  }
  const Scene s = test::scene_from_json(R"({"indenter": {"guide": "free", "workspace_max": [5, 5, 5]}})");
  EXPECT_EQ(s.indenter.guide, ToolGuide::free);
  EXPECT_EQ(options_of(s).tool_guide, ToolGuide::free);
  EXPECT_EQ(s.indenter.workspace_max, Vec3(5, 5, 5));
  EXPECT_FALSE(std::isfinite(s.indenter.workspace_min[0]));  // derived from the body at the build
}

}  // namespace
}  // namespace palpate
