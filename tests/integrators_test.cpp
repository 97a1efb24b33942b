// Time integrators on a free elastic cube: energy conservation to the
// integrator's order, dissipation by implicit Euler and by damping, fixed
// particles staying put.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/health.h"
#include "core/solid.h"
#include "core/state.h"
#include "core/step.h"
#include "test_util.h"

namespace palpate {
namespace {

// A 5^3 jittered cube, no fixed faces, indenter far above and idle, no damping.
std::string free_cube(const std::string& integrator, double dt, double damping = 0.0,
                      const std::string& fixed = "[]") {
  return R"({"body": {"box": {"min": [0,0,0], "max": [1,1,1]},
                      "distribution": {"type": "jittered_grid", "per_edge": 5, "jitter": 0.2, "seed": 3}},
             "mls": {"neighbors": 16, "support_factor": 1.5, "volumes": "lattice"},
             "material": {"young_modulus": 1000, "poisson_ratio": 0.3, "density": 1000},
             "fixed": )" + fixed + R"(,
             "indenter": {"radius": 0.1, "mass": 1, "position": [0.5, 0.5, 5]},
             "integrator": {"type": ")" + integrator + R"(", "dt": )" + std::to_string(dt) +
         R"(, "damping": )" + std::to_string(damping) + "}}";
}

double total_energy(const Model& m, const State& s) {
  double kinetic = 0;
  for (int i = 0; i < m.particle_count; ++i) kinetic += 0.5 * m.mass[i] * s.velocity.col(i).squaredNorm();
  return kinetic + elastic_energy(m, s.position);
}

// A smooth initial velocity field (a twist plus a stretch), 0.05 m/s. A state set by
// hand restarts the health checks' energy budget (health.h).
void set_initial_velocity(const Model& m, const Options& opt, State& s) {
  for (int i = 0; i < m.particle_count; ++i) {
    const Vec3 X = m.rest_position.col(i) - Vec3(0.5, 0.5, 0.5);
    s.velocity.col(i) = 0.05 * Vec3(-X[1] * X[2] + X[0], X[0] * X[2], 0.5 * X[2] * X[2]);
  }
  reset_health(m, opt, s);
}

// Energy history over `duration` seconds.
std::vector<double> energy_history(const std::string& integrator, double dt, double duration, double damping = 0) {
  const test::Setup setup = test::setup_from_json(free_cube(integrator, dt, damping));
  const Model& m = setup.model;
  const Options& opt = setup.opt;
  State s = make_state(m, opt);
  set_initial_velocity(m, opt, s);
  std::vector<double> energy{total_energy(m, s)};
  const int steps = static_cast<int>(std::lround(duration / dt));
  for (int k = 0; k < steps; ++k) {
    EXPECT_EQ(step(m, opt, s), StepStatus::ok);
    energy.push_back(total_energy(m, s));
  }
  return energy;
}

double max_relative_deviation(const std::vector<double>& e) {
  double worst = 0;
  for (double v : e) worst = std::max(worst, std::abs(v - e.front()) / e.front());
  return worst;
}

TEST(Integrators, Rk4ConservesEnergyToFourthOrder) {
  const double coarse = max_relative_deviation(energy_history("rk4", 0.02, 2.0));
  const double fine = max_relative_deviation(energy_history("rk4", 0.01, 2.0));
  EXPECT_LT(coarse, 1e-3);
  // Halving dt divides a fourth-order error by 16 (allow 10 for the mix of modes).
  EXPECT_GT(coarse / fine, 10.0) << "coarse " << coarse << " fine " << fine;
}

TEST(Integrators, SymplecticEulerEnergyErrorIsBoundedAndFirstOrder) {
  const std::vector<double> coarse = energy_history("symplectic_euler", 0.01, 4.0);
  const std::vector<double> fine = energy_history("symplectic_euler", 0.005, 4.0);
  const double e_coarse = max_relative_deviation(coarse), e_fine = max_relative_deviation(fine);
  EXPECT_LT(e_coarse, 0.05);
  EXPECT_GT(e_coarse / e_fine, 1.6);  // first order: about 2
  EXPECT_LT(e_coarse / e_fine, 2.6);
  // No drift: the second half of the run deviates no more than the first half.
  const size_t half = coarse.size() / 2;
  const std::vector<double> first(coarse.begin(), coarse.begin() + half), second(coarse.begin() + half, coarse.end());
  double dev_first = 0, dev_second = 0;
  for (double v : first) dev_first = std::max(dev_first, std::abs(v - coarse.front()));
  for (double v : second) dev_second = std::max(dev_second, std::abs(v - coarse.front()));
  EXPECT_LT(dev_second, 1.5 * dev_first);
}

TEST(Integrators, ImplicitEulerDissipatesMonotonically) {
  const std::vector<double> e = energy_history("implicit_euler", 0.05, 3.0);
  for (size_t k = 1; k < e.size(); ++k) EXPECT_LE(e[k], e[k - 1] * (1 + 1e-9)) << "step " << k;
  EXPECT_LT(e.back(), 0.9 * e.front());
}

TEST(Integrators, MassProportionalDampingRemovesEnergy) {
  const std::vector<double> e = energy_history("rk4", 0.01, 2.0, /*damping=*/2.0);
  // Rigid-body and elastic motion alike decay like exp(-c t) in kinetic energy; a loose bound.
  EXPECT_LT(e.back(), 0.2 * e.front());
  for (size_t k = 1; k < e.size(); ++k) EXPECT_LE(e[k], e[k - 1] * (1 + 1e-9));
}

TEST(Integrators, FixedParticlesStayPut) {
  for (const char* integrator : {"rk4", "symplectic_euler", "implicit_euler"}) {
    const test::Setup setup = test::setup_from_json(free_cube(integrator, 0.01, 0.0, R"(["bottom"])"));
    const Model& m = setup.model;
    const Options& opt = setup.opt;
    State s = make_state(m, opt);
    set_initial_velocity(m, opt, s);
    for (int i = 0; i < m.particle_count; ++i)
      if (m.fixed[i]) s.velocity.col(i).setZero();
    for (int k = 0; k < 50; ++k) ASSERT_EQ(step(m, opt, s), StepStatus::ok);
    double moved_fixed = 0, moved_free = 0;
    for (int i = 0; i < m.particle_count; ++i) {
      const double d = (s.position.col(i) - m.rest_position.col(i)).norm();
      (m.fixed[i] ? moved_fixed : moved_free) = std::max(m.fixed[i] ? moved_fixed : moved_free, d);
    }
    EXPECT_EQ(moved_fixed, 0.0) << integrator;
    EXPECT_GT(moved_free, 1e-3) << integrator;
  }
}

}  // namespace
}  // namespace palpate
