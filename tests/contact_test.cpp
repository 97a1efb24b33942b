// Frictionless unilateral contact with Lagrange multipliers: the LCP solver,
// Signorini conditions along a loading, global force balance at rest, release.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "analysis/rest.h"
#include "core/contact.h"
#include "core/indentation.h"
#include "core/solid.h"
#include "core/state.h"
#include "core/step.h"
#include "test_util.h"

namespace palpate {
namespace {

TEST(SignoriniLcp, SolutionIsComplementaryOnRandomSpdProblems) {
  std::mt19937 rng(1);
  std::normal_distribution<double> normal;
  Workspace work;
  for (int trial = 0; trial < 50; ++trial) {
    const int m = 1 + trial % 17;
    Eigen::MatrixXd B(m + 2, m);
    for (int r = 0; r < B.rows(); ++r)
      for (int c = 0; c < m; ++c) B(r, c) = normal(rng);
    // Row-major storage of W = B^T B + 0.1 I (symmetric, so the layout is the same).
    const Eigen::MatrixXd W = B.transpose() * B + 0.1 * Eigen::MatrixXd::Identity(m, m);
    Eigen::VectorXd g(m);
    for (int a = 0; a < m; ++a) g[a] = normal(rng);
    Eigen::VectorXd lambda(m);
    const int iterations = solve_signorini_lcp(m, W.data(), g.data(), lambda.data(), 1e-12, 200, work);
    ASSERT_GT(iterations, 0) << "trial " << trial;
    const Eigen::VectorXd w = g + W * lambda;
    for (int a = 0; a < m; ++a) {
      EXPECT_GE(lambda[a], 0.0);
      EXPECT_GE(w[a], -1e-9);
      EXPECT_LT(std::abs(lambda[a] * w[a]), 1e-9);
    }
  }
}

// The explicit integrators' operator W = D + U U^T (2.4), solved through (2.19): on problems of
// a contact's shape (up to 200 candidates, a tool free along some axes only, stiff and
// soft particles), the solution is the unique one of the LCP with W formed densely (W is
// SPD), whatever active set pivoting starts from.
TEST(SignoriniLcp, LumpedOperatorGivesTheDenseSolutionFromAnyStart) {
  std::mt19937 rng(2);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  Workspace work;
  const Vec3 axes_of_trial[3] = {Vec3(1, 1, 1), Vec3(0, 0, 1), Vec3(0, 0, 0)};
  int largest_pivots = 0;
  for (int trial = 0; trial < 30; ++trial) {
    const int m = 1 + (trial * 37) % 200;
    const Vec3 axes = axes_of_trial[trial % 3];
    const double dt = 1e-3, tool_mass = 0.05 + uniform(rng);
    Eigen::VectorXd d(m), g(m);
    Eigen::MatrixXd U(m, 3);
    for (int a = 0; a < m; ++a) {
      d[a] = dt * dt / (1e-5 * (1.0 + 100.0 * uniform(rng)));  // particle masses over two decades
      const Vec3 n = Vec3(normal(rng), normal(rng), normal(rng)).normalized();
      U.row(a) = (dt * (axes / tool_mass).cwiseSqrt()).cwiseProduct(n).transpose();
      g[a] = 1e-4 * normal(rng);
    }
    const Eigen::MatrixXd W = Eigen::MatrixXd(d.asDiagonal()) + U * U.transpose();
    Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> U_rows = U;
    Eigen::VectorXd dense(m), lumped(m);
    ASSERT_GT(solve_signorini_lcp(m, W.data(), g.data(), dense.data(), 1e-14, 1000, work), 0) << "trial " << trial;
    std::vector<int> start(m);
    for (int guess = 0; guess < 3; ++guess) {
      for (int a = 0; a < m; ++a) start[a] = guess == 0 ? 0 : guess == 1 ? 1 : uniform(rng) < 0.5;
      const int pivots = solve_signorini_lcp_lumped(m, d.data(), U_rows.data(), g.data(), lumped.data(), 1e-14, 1000,
                                                    work, start.data());
      ASSERT_GT(pivots, 0) << "trial " << trial << " start " << guess;
      largest_pivots = std::max(largest_pivots, pivots);
      const Eigen::VectorXd w = g + W * lumped;
      for (int a = 0; a < m; ++a) {
        EXPECT_GE(lumped[a], 0.0);
        EXPECT_GE(w[a], -1e-13) << "trial " << trial << " candidate " << a;
        EXPECT_LT(std::abs(lumped[a] * w[a]), 1e-13 * std::max(1.0, lumped[a]));
      }
      EXPECT_LT((lumped - dense).norm(), 1e-9 * std::max(1.0, dense.norm())) << "trial " << trial << " start " << guess;
    }
  }
  EXPECT_LE(largest_pivots, 1000);  // pivoting settled every time (PGS would add 1000)
}

// Block pivoting (docs/physics.md §2, "The LCP solver"): a contact's LCP from a cold start
// (no candidate active, or every one) settles in a few block pivots (3 here), not one pivot
// per contact as single pivots do from the empty set (45 or more here). Problems shaped as
// above, 100-190 candidates under a tool, about half of them ending in contact.
TEST(SignoriniLcp, BlockPivotsSettleAColdStartInAFewPivots) {
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  Workspace work;
  int largest = 0, smallest_active = 1 << 30;
  for (int trial = 0; trial < 10; ++trial) {
    const int m = 100 + 10 * trial;
    const double dt = 1e-3, tool_mass = 0.05 + uniform(rng);
    Eigen::VectorXd d(m), g(m), lambda(m);
    Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> U(m, 3);
    for (int a = 0; a < m; ++a) {
      d[a] = dt * dt / (1e-5 * (1.0 + 100.0 * uniform(rng)));
      const Vec3 n = Vec3(0.3 * normal(rng), 0.3 * normal(rng), -1).normalized();  // under a tool
      U.row(a) = (dt / std::sqrt(tool_mass)) * n.transpose();
      g[a] = 1e-4 * normal(rng);
    }
    for (int all = 0; all < 2; ++all) {
      const std::vector<int> start(m, all);
      const int pivots = solve_signorini_lcp_lumped(m, d.data(), U.data(), g.data(), lambda.data(), 1e-14, 1000, work,
                                                    start.data());
      ASSERT_GT(pivots, 0) << "trial " << trial;
      largest = std::max(largest, pivots);
      int active = 0;
      for (int a = 0; a < m; ++a) active += lambda[a] > 0;
      smallest_active = std::min(smallest_active, active);
    }
  }
  EXPECT_GT(smallest_active, 20);  // the problems are not trivial: dozens of contacts
  EXPECT_LE(largest, 12) << "block pivoting took " << largest << " pivots";
}

std::string pressed_block(const std::string& integrator, double dt, const std::string& model = "mls") {
  return R"({"model": ")" + model + R"(", "body": {"box": {"min": [-0.5,-0.5,-1], "max": [0.5,0.5,0]},
                      "distribution": {"type": "grid", "per_edge": 8}},
             "mls": {"volumes": "lattice"},
             "material": {"young_modulus": 10000, "poisson_ratio": 0.3, "density": 1000},
             "indenter": {"radius": 0.3, "mass": 0.5},
             "contact": {"tolerance": 1e-7},
             "integrator": {"type": ")" + integrator + R"(", "dt": )" + std::to_string(dt) +
         R"(, "damping": 10},
             "verify": {"rest": {"velocity_tolerance": 1e-6, "force_tolerance": 1e-4, "window": 0.05}}})";
}

// Smallest actual (nonlinear) gap between the sphere and any particle, m.
double min_gap(const Model& m, const State& s) {
  double gap = INFINITY;
  for (int i = 0; i < m.particle_count; ++i)
    gap = std::min(gap, (s.position.col(i) - s.indenter_center).norm() - m.indenter_radius);
  return gap;
}

void press_release(const std::string& integrator, double dt, const std::string& model = "mls") {
  SCOPED_TRACE(integrator + " " + model);
  const test::Setup setup = test::setup_from_json(pressed_block(integrator, dt, model));
  const Model& m = setup.model;
  const Options& opt = setup.opt;
  State s = make_state(m, opt);
  const double force = 20.0;
  s.force_command = press_down(force);
  RestMonitor rest(setup.scene.verify.rest);
  bool at_rest = false;
  int steps = 0;
  size_t most_contacts = 0;
  for (; steps < static_cast<int>(20.0 / dt) && !at_rest; ++steps) {
    ASSERT_EQ(step(m, opt, s), StepStatus::ok) << "step " << steps;
    for (double lambda : s.contact_normal_force) ASSERT_GT(lambda, 0.0);
    most_contacts = std::max(most_contacts, s.contact_index.size());
    // Signorini: no penetration beyond the solver tolerance plus the second-order
    // error of the linearised sphere motion.
    ASSERT_GT(min_gap(m, s), -1e-5) << "step " << steps;
    at_rest = rest.update(s, opt);
  }
  ASSERT_TRUE(at_rest) << "no rest after " << steps << " steps";
  EXPECT_GT(most_contacts, 0u);
  EXPECT_GT(indentation(m, s), 0.0);
  // At rest the contact forces on the particles add up to the command (pointing down)...
  Vec3 contact_sum = Vec3::Zero();
  for (size_t c = 0; c < s.contact_index.size(); ++c) contact_sum += s.contact_force.col(static_cast<Eigen::Index>(c));
  EXPECT_NEAR(contact_sum[2], -force, 1e-3 * force);
  EXPECT_NEAR(s.indenter_contact_force[2], force, 1e-3 * force);
  EXPECT_NEAR(s.indenter_contact_force.head<2>().norm(), 0.0, 1e-3 * force);  // centred: no lateral force
  // ... and the fixed supports carry it: internal forces sum to zero, free particles
  // (damping forces c m v <= 10 * 800 kg * 1e-6 m/s = 0.008 N at rest)
  // are in equilibrium with the contact, so the fixed particles' internal forces
  // balance the command (an independent global balance).
  Points f(3, m.particle_count);
  elastic_forces(m, s.position, f);
  Vec3 support = Vec3::Zero();
  double free_residual = 0;
  for (int i = 0; i < m.particle_count; ++i) {
    if (m.fixed[i]) support += f.col(i);
  }
  Points residual = f;
  for (size_t c = 0; c < s.contact_index.size(); ++c)
    residual.col(s.contact_index[c]) += s.contact_force.col(static_cast<Eigen::Index>(c));
  for (int i = 0; i < m.particle_count; ++i)
    if (!m.fixed[i]) free_residual = std::max(free_residual, residual.col(i).norm());
  EXPECT_NEAR(support[2], -force, 5e-4 * force);
  EXPECT_LT(free_residual, 5e-4 * force);

  // Unilateral: pulling the indenter up releases the contact, no force sticks.
  s.force_command = press_down(-5.0);
  for (int k = 0; k < static_cast<int>(1.0 / dt); ++k) ASSERT_EQ(step(m, opt, s), StepStatus::ok);
  EXPECT_TRUE(s.contact_index.empty());
  EXPECT_EQ(s.indenter_contact_force, Vec3::Zero());
  EXPECT_GT(min_gap(m, s), 0.0);
}

TEST(SphereContact, SymplecticEuler) { press_release("symplectic_euler", 1e-3); }
TEST(SphereContact, Rk4) { press_release("rk4", 1e-3); }
TEST(SphereContact, ImplicitEuler) { press_release("implicit_euler", 1e-2); }
TEST(SphereContact, HexFemImplicitEuler) { press_release("implicit_euler", 1e-2, "hex_fem"); }
TEST(SphereContact, HexFemSymplecticEuler) { press_release("symplectic_euler", 1e-3, "hex_fem"); }

}  // namespace
}  // namespace palpate
