// Implicit Euler's coupled contact (docs/physics.md §2, (2.17), (2.18)): the compliance
// cache and the splitting reach the LCP solution of the step's own operator, the one the
// Delassus operator formed exactly (one CG solve per candidate,
// analysis/exact_coupled_contact.h) gives, to the CG tolerance, whatever the cache holds;
// a running simulation reuses the columns; the rest state under a pressed tool is the
// static equilibrium the explicit integrators reach.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "analysis/exact_coupled_contact.h"
#include "analysis/rest.h"
#include "core/indentation.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/step.h"
#include "test_util.h"

namespace palpate {
namespace {

// A 1 m block, fixed at the bottom and sides, the tool (radius 0.3 m) on its top face.
std::string block(const std::string& model, const std::string& guide = "vertical", int per_edge = 8) {
  return R"({"model": ")" + model + R"(", "body": {"box": {"min": [-0.5,-0.5,-1], "max": [0.5,0.5,0]},
                      "distribution": {"type": "grid", "per_edge": )" + std::to_string(per_edge) + R"(}},
             "mls": {"volumes": "lattice"},
             "material": {"young_modulus": 10000, "poisson_ratio": 0.3, "density": 1000)" +
         (model == "mls" ? R"(, "law": "corotational")" : "") + R"(},
             "fixed": ["bottom", "sides"],
             "indenter": {"radius": 0.3, "mass": 0.5, "guide": ")" + guide + R"("},
             "contact": {"tolerance": 1e-7},
             "integrator": {"type": "implicit_euler", "dt": 0.01, "damping": 10},
             "verify": {"rest": {"velocity_tolerance": 1e-6, "force_tolerance": 1e-4, "window": 0.05}}})";
}

// How far one step of core's solve differs from the exact-Delassus one from the same state,
// relative to the step's scales: the positions to the step's largest particle motion, the
// velocities to the largest speed, the contact forces (per particle) and the tool's to the
// largest force.
struct Difference {
  double position = 0, velocity = 0, force = 0, tool = 0;
  double worst() const { return std::max({position, velocity, force, tool}); }
};

Points forces_by_particle(const Model& m, const State& s) {
  Points f = Points::Zero(3, m.particle_count);
  for (size_t c = 0; c < s.contact_index.size(); ++c) f.col(s.contact_index[c]) = s.contact_force.col(static_cast<Eigen::Index>(c));
  return f;
}

// Steps `s` with step() and a copy of it with the exact Delassus operator; returns how far apart they ended.
Difference step_against_exact(const Model& m, const Options& opt, State& s) {
  State exact = s;
  const Points start = s.position;
  EXPECT_EQ(step(m, opt, s), StepStatus::ok);
  EXPECT_EQ(step_implicit_euler_exact(m, opt, exact), StepStatus::ok);
  Difference d;
  const double motion = std::max((exact.position - start).cwiseAbs().maxCoeff(), 1e-300);
  d.position = (s.position - exact.position).cwiseAbs().maxCoeff() / motion;
  d.velocity = (s.velocity - exact.velocity).cwiseAbs().maxCoeff() / std::max(exact.velocity.cwiseAbs().maxCoeff(), 1e-300);
  const Points f = forces_by_particle(m, s), f_exact = forces_by_particle(m, exact);
  const double force_scale = std::max(f_exact.cwiseAbs().maxCoeff(), 1e-300);
  d.force = (f - f_exact).cwiseAbs().maxCoeff() / force_scale;
  d.tool = std::max((s.indenter_contact_force - exact.indenter_contact_force).norm() /
                        std::max(exact.indenter_contact_force.norm(), 1e-300),
                    (s.indenter_center - exact.indenter_center).norm() / motion);
  return d;
}

// Presses the tool in with `force` for `steps` implicit-Euler steps, each checked against
// the exact Delassus operator; returns the largest difference and the columns computed.
struct PressRecord {
  double worst = 0;
  int columns = 0, most_candidates = 0, steps_with_contact = 0;
};
PressRecord press_against_exact(const Model& m, const Options& opt, State& s, double force, int steps) {
  PressRecord r;
  s.force_command = press_down(force);
  for (int k = 0; k < steps; ++k) {
    const Difference d = step_against_exact(m, opt, s);
    if (std::getenv("PALPATE_TEST_VERBOSE"))
      std::printf("step %d: candidates %zu contacts %zu columns %d splitting %d cg %d/%d  diff x %.2e v %.2e f %.2e tool %.2e\n",
                  k, s.out.contact_candidate.size(), s.contact_index.size(), s.out.contact_columns,
                  s.out.contact_splitting_iterations, s.out.contact_cg_solves, s.out.contact_cg_iterations, d.position,
                  d.velocity, d.force, d.tool);
    r.worst = std::max(r.worst, d.worst());
    r.columns += s.out.contact_columns;
    r.most_candidates = std::max(r.most_candidates, static_cast<int>(s.out.contact_candidate.size()));
    r.steps_with_contact += !s.contact_index.empty();
  }
  return r;
}

TEST(ImplicitContact, MatchesTheExactDelassusOperatorAlongAPress) {
  const test::Setup setup = test::setup_from_json(block("mls", "vertical", 12));
  State s = make_state(setup.model, setup.opt);
  const PressRecord r = press_against_exact(setup.model, setup.opt, s, 60.0, 60);
  EXPECT_GT(r.steps_with_contact, 50);
  EXPECT_GT(r.most_candidates, 4);
  EXPECT_LT(r.worst, 1e-6);
}

TEST(ImplicitContact, MatchesTheExactDelassusOperatorForTheHexFemAndAFreeCoupledTool) {
  {
    SCOPED_TRACE("hex FEM");
    const test::Setup setup = test::setup_from_json(block("hex_fem", "vertical", 10));
    State s = make_state(setup.model, setup.opt);
    const PressRecord r = press_against_exact(setup.model, setup.opt, s, 60.0, 40);
    EXPECT_GT(r.steps_with_contact, 30);
    EXPECT_LT(r.worst, 1e-6);
  }
  {
    // A free tool held off-centre by a stiff virtual coupling below the surface: the
    // tool's three translations and its effective mass (2.6) enter W and the splitting.
    SCOPED_TRACE("free tool, coupling");
    const test::Setup setup = test::setup_from_json(block("mls", "free", 10));
    Options opt = setup.opt;
    opt.coupling.stiffness = 2000.0;
    opt.coupling.damping = 5.0;
    State s = make_state(setup.model, opt);
    s.tool_target = setup.model.indenter_start + Vec3(0.07, -0.05, -0.08);
    const PressRecord r = press_against_exact(setup.model, opt, s, 0.0, 40);
    EXPECT_GT(r.steps_with_contact, 30);
    EXPECT_GT(r.most_candidates, 4);
    EXPECT_LT(r.worst, 1e-6);
  }
}

// The cache decides the cost, never the answer: with its entries a little off, the step
// still ends where the exact Delassus operator takes it, after more splitting iterations;
// far off, the splitting recomputes the columns on its way to the same solution.
TEST(ImplicitContact, AWrongCacheCostsIterationsNotAccuracy) {
  const test::Setup setup = test::setup_from_json(block("mls", "vertical", 12));
  const Model& m = setup.model;
  const Options& opt = setup.opt;
  State s = make_state(m, opt);
  press_against_exact(m, opt, s, 60.0, 30);
  ASSERT_GT(s.contact_index.size(), 4u);
  State reference = s;
  ASSERT_EQ(step(m, opt, reference), StepStatus::ok);
  const int usual = reference.out.contact_splitting_iterations;
  for (double scale : {0.9, 1.1, 0.5, 2.0}) {
    SCOPED_TRACE(scale);
    const bool far_off = scale < 0.8 || scale > 1.2;
    State wrong = s;
    ComplianceCache& c = wrong.work.compliance;
    for (int r = 0; r < c.capacity; ++r)
      for (int k = 0; k < c.capacity; ++k) c.entry[static_cast<size_t>(r) * c.capacity + k] *= r == k ? scale : 1.0 / scale;
    const Difference d = step_against_exact(m, opt, wrong);
    EXPECT_LT(d.worst(), 1e-6);
    if (far_off) {
      EXPECT_EQ(wrong.out.contact_columns, static_cast<int>(wrong.out.contact_candidate.size()));
    } else {
      EXPECT_GT(wrong.out.contact_splitting_iterations, usual);
      EXPECT_EQ(wrong.out.contact_columns, 0);  // the splitting converged on the wrong W~
    }
  }
}

// A running simulation computes columns only for new candidates: pressed to rest, a step
// takes a few CG solves of A for its contact, not one per candidate; a change of dt starts
// the cache again.
TEST(ImplicitContact, ARunningSimulationReusesTheColumns) {
  const test::Setup setup = test::setup_from_json(block("mls", "vertical", 12));
  const Model& m = setup.model;
  Options opt = setup.opt;
  State s = make_state(m, opt);
  s.force_command = press_down(60.0);
  int columns = 0;
  for (int k = 0; k < 150; ++k) {
    ASSERT_EQ(step(m, opt, s), StepStatus::ok);
    columns += s.out.contact_columns;
  }
  const int candidates = static_cast<int>(s.out.contact_candidate.size());
  ASSERT_GT(candidates, 8);
  EXPECT_LT(columns, 3 * candidates);  // each particle's column about once
  for (int k = 0; k < 20; ++k) {
    ASSERT_EQ(step(m, opt, s), StepStatus::ok);
    EXPECT_EQ(s.out.contact_columns, 0);
    EXPECT_LE(s.out.contact_cg_solves, 6);
    EXPECT_LE(s.out.contact_splitting_iterations, 8);
  }
  opt.integrator.dt *= 0.5;
  ASSERT_EQ(step(m, opt, s), StepStatus::ok);
  EXPECT_EQ(s.out.contact_columns, static_cast<int>(s.out.contact_candidate.size()));
}

// The rest state under a pressed tool is the static equilibrium: implicit Euler (10 ms)
// stops where symplectic Euler (1 ms) does, on a tetrahedral-mesh cloud (the haptic scene's).
TEST(ImplicitContact, RestStateIsTheSymplecticEulerOne) {
  const test::Setup setup = test::setup_from(load_scene(std::string(PALPATE_SOURCE_DIR) + "/scenes/hertz_cube_haptic.json"));
  const Model& m = setup.model;
  const double force = 115.8;
  RestSpec rest = setup.scene.verify.rest;
  auto press = [&](IntegratorType type, double dt) {
    Options opt = setup.opt;
    opt.integrator.type = type;
    opt.integrator.dt = dt;
    State s = make_state(m, opt);
    const PressResult r = press_to_rest(m, opt, rest, s, force);
    EXPECT_TRUE(r.at_rest);
    EXPECT_EQ(r.status, StepStatus::ok);
    return s;
  };
  const State implicit = press(IntegratorType::implicit_euler, 0.01);
  const State explicit_ = press(IntegratorType::symplectic_euler, 0.001);
  const double d_implicit = indentation(m, implicit), d_explicit = indentation(m, explicit_);
  std::printf("indentation: implicit Euler %.9f m, symplectic Euler %.9f m (%zu / %zu contacts)\n", d_implicit, d_explicit,
              implicit.contact_index.size(), explicit_.contact_index.size());
  EXPECT_GT(d_explicit, 0.01);
  EXPECT_NEAR(d_implicit, d_explicit, 2e-4 * d_explicit);
  EXPECT_NEAR(implicit.indenter_contact_force[2], force, 1e-3 * force);
  double worst = 0, scale = 0;
  for (int i = 0; i < m.particle_count; ++i) {
    worst = std::max(worst, (implicit.position.col(i) - explicit_.position.col(i)).norm());
    scale = std::max(scale, (explicit_.position.col(i) - m.rest_position.col(i)).norm());
  }
  EXPECT_LT(worst, 1e-3 * scale);
}

}  // namespace
}  // namespace palpate
