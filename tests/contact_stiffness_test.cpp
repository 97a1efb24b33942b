// The local contact model (core/contact_stiffness.h, docs/physics.md §2 "The local contact
// model", (2.7)-(2.15)) against independent truths:
//  - K against central finite differences of full static solves with the tool held at
//    x0 +- h e_j (analysis/static_contact.h relax_to_rest_at: the nonlinear equilibrium of
//    the step's own contact, found by continuation, nothing shared with (2.10)), for the
//    MLS solid and the linear hex FEM, at an off-centre site where the lateral terms are
//    not zero; the difference falls as h^2;
//  - F0 + K dx against the static force at x0 + dx: the error is second order in |dx|;
//  - the validity radius against the static solves: the active set holds inside it and
//    changes just beyond it along the limiting direction; without contact it is the
//    tool's distance to the body;
//  - K_zz against the slope of the exact linear solve (LinearStaticContact at two
//    forces) and against Hertz's dF/dd = (3/2) F / d on a well-resolved graded FEM cube;
//  - the stiffness at first touch (2.20), computed out of contact, against the static
//    solves with the tool held just past the touch;
//  - warm starts, the converged flag, no allocation after the first call, errors.
#include <gtest/gtest.h>
#include <cstdio>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "analysis/static_contact.h"
#include "core/contact_stiffness.h"
#include "core/hertz.h"
#include "core/scene.h"
#include "core/state.h"
#include "test_util.h"

// Counts the heap allocations of the whole program: operator new (std::vector and the
// like), and malloc, calloc and realloc (Eigen's dynamic matrices) through the linker's
// --wrap (tests/CMakeLists.txt), which covers the static core library's calls. The test
// reads the count around evaluate(). free is wrapped only for the deletes below to call
// the real one.
namespace {
std::atomic<long> g_allocations{0};
}
extern "C" {
void* __real_malloc(std::size_t);
void* __real_calloc(std::size_t, std::size_t);
void* __real_realloc(void*, std::size_t);
void __real_free(void*);
void __wrap_free(void* p) { __real_free(p); }
void* __wrap_malloc(std::size_t size) {
  ++g_allocations;
  return __real_malloc(size);
}
void* __wrap_calloc(std::size_t count, std::size_t size) {
  ++g_allocations;
  return __real_calloc(count, size);
}
void* __wrap_realloc(void* p, std::size_t size) {
  ++g_allocations;
  return __real_realloc(p, size);
}
}
void* operator new(std::size_t size) {
  ++g_allocations;
  if (void* p = __real_malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size) { return operator new(size); }
void operator delete(void* p) noexcept { __real_free(p); }
void operator delete[](void* p) noexcept { __real_free(p); }
void operator delete(void* p, std::size_t) noexcept { __real_free(p); }
void operator delete[](void* p, std::size_t) noexcept { __real_free(p); }

namespace palpate {
namespace {

// A coarse MLS cube (8^3 on the default 2 m block, bottom and sides fixed) with the
// corotational law (its tangent includes the rotation's derivative, (1.7)).
const char* kMlsCube = R"({"body": {"distribution": {"type": "grid", "per_edge": 8}},
    "mls": {"neighbors": 18, "support_factor": 1.05, "support_rule": "kth_distance", "volumes": "lattice"},
    "material": {"law": "corotational"},
    "integrator": {"type": "symplectic_euler", "dt": 0.001, "damping": 10}})";
// The linear hex FEM on the same lattice.
const char* kFemCube = R"({"model": "hex_fem", "hex_fem": {"formulation": "linear"},
    "body": {"distribution": {"type": "grid", "per_edge": 8}},
    "integrator": {"type": "implicit_euler", "dt": 0.01, "damping": 10}})";

// The height of the tool's centre at which the sphere touches the undeformed body at
// horizontal position (x, y): the highest particle under it.
double touch_height(const Model& m, double x, double y) {
  double z = -INFINITY;
  const double R = m.indenter_radius;
  for (int i = 0; i < m.particle_count; ++i) {
    const Vec3 X = m.rest_position.col(i);
    const double r2 = (X[0] - x) * (X[0] - x) + (X[1] - y) * (X[1] - y);
    if (r2 < R * R) z = std::max(z, X[2] + std::sqrt(R * R - r2));
  }
  return z;
}

// The active set as a sorted list (the contact stage lists it in its own order).
std::vector<int> active_set(const State& s) {
  std::vector<int> a = s.contact_index;
  std::sort(a.begin(), a.end());
  return a;
}

// The static state with the tool held at c (from `start`).
State held_at(const test::Setup& s, const State& start, const Vec3& c) {
  State t = start;
  const StaticSolution sol = relax_to_rest_at(s.model, s.opt, t, c);
  EXPECT_TRUE(sol.converged) << sol.message;
  return t;
}

// Central differences of the held static force, column j = (F(c + h e_j) - F(c - h e_j)) / 2h.
Mat3 finite_difference(const test::Setup& s, const State& at, double h) {
  Mat3 fd;
  for (int j = 0; j < 3; ++j) {
    const Vec3 e = h * Vec3::Unit(j);
    const State plus = held_at(s, at, at.indenter_center + e), minus = held_at(s, at, at.indenter_center - e);
    EXPECT_EQ(active_set(plus), active_set(at)) << "the active set changed within h = " << h;
    EXPECT_EQ(active_set(minus), active_set(at)) << "the active set changed within h = " << h;
    fd.col(j) = (plus.indenter_contact_force - minus.indenter_contact_force) / (2 * h);
  }
  return fd;
}

double max_abs(const Mat3& A) { return A.cwiseAbs().maxCoeff(); }

// K against the finite differences at h = 2 and 1 mm: the difference is the difference
// scheme's O(h^2) error (it falls by 4 when h halves) and is below 2e-5 |K| at 1 mm
// (measured: 1.1e-5 MLS, 4e-6 FEM). A wrong sign or a missing normal-rotation term is
// 1e-2 |K| and more.
void expect_matches_finite_difference(const test::Setup& s, const State& x0, const LocalContactModel& lm) {
  const Mat3& K = lm.stiffness;
  const double scale = max_abs(K);
  double previous = 0.0;
  for (double h : {2e-3, 1e-3}) {
    const Mat3 fd = finite_difference(s, x0, h);
    const double error = max_abs(fd - K);
    if (previous > 0) {
      EXPECT_GT(previous / error, 3.0) << "h = " << h << ": the difference does not fall as h^2";
      EXPECT_LT(previous / error, 5.0) << "h = " << h << ": the difference does not fall as h^2";
    }
    previous = error;
    if (h == 1e-3) {
      EXPECT_LT(error, 2e-5 * scale) << "K\n" << K << "\nfinite difference\n" << fd;
    }
  }
  // K = -d^2 Pi / dc^2 (2.13) is symmetric.
  EXPECT_LT(max_abs(K - K.transpose()), 1e-6 * scale) << K;
}

struct Site {
  test::Setup setup;
  State state;  // static, tool held at the site
  ContactStiffness stiffness;
  LocalContactModel local;
};

// The static state pressed `depth` below the touch height at (x, y), and its local model.
Site site(const char* json, double x, double y, double depth) {
  test::Setup s = test::setup_from_json(json);
  State start = make_state(s.model, s.opt);
  State at = held_at(s, start, Vec3(x, y, touch_height(s.model, x, y) - depth));
  ContactStiffness cs(s.model);
  const LocalContactModel lm = cs.evaluate(s.model, at);
  return {std::move(s), std::move(at), std::move(cs), lm};
}

TEST(ContactStiffness, MeshlessMatchesFiniteDifferencesOfHeldStaticSolves) {
  Site t = site(kMlsCube, 0.07, 0.03, 0.03);
  const LocalContactModel& lm = t.local;
  ASSERT_TRUE(lm.converged);
  ASSERT_GE(lm.active_count, 2);
  EXPECT_EQ(lm.force, t.state.indenter_contact_force);
  EXPECT_EQ(lm.origin, t.state.indenter_center);
  const Mat3& K = lm.stiffness;
  // Off centre the lateral terms are not small: they are what the finite difference checks.
  EXPECT_GT(std::abs(K(0, 2)), 0.1 * std::abs(K(2, 2)));
  EXPECT_GT(std::abs(K(1, 2)), 0.02 * std::abs(K(2, 2)));
  EXPECT_LT(K(2, 2), 0.0);  // pressing deeper pushes back harder
  expect_matches_finite_difference(t.setup, t.state, lm);
  // Not negative semidefinite in general: off centre, over a particle, moving sideways the
  // tool is pushed further sideways (a positive eigenvalue, confirmed by the differences).
  const Eigen::SelfAdjointEigenSolver<Mat3> eig(0.5 * (K + K.transpose()));
  EXPECT_GT(eig.eigenvalues().maxCoeff(), 0.0) << K;
}

TEST(ContactStiffness, MeshlessIsNegativeSemidefiniteAtTheSymmetricCentre) {
  // Centred between four particles the lattice is a bowl: every direction is restoring.
  Site t = site(kMlsCube, 0.0, 0.0, 0.03);
  const Mat3& K = t.local.stiffness;
  ASSERT_EQ(t.local.active_count, 4);
  const Eigen::SelfAdjointEigenSolver<Mat3> eig(0.5 * (K + K.transpose()));
  EXPECT_LT(eig.eigenvalues().maxCoeff(), 0.0) << K;
  EXPECT_NEAR(K(0, 0), K(1, 1), 1e-3 * std::abs(K(0, 0)));  // the lattice's symmetry
  // The lateral column against the held static solves (the others as off centre, above).
  const double h = 1e-3;
  const State plus = held_at(t.setup, t.state, t.local.origin + h * Vec3::UnitX());
  const State minus = held_at(t.setup, t.state, t.local.origin - h * Vec3::UnitX());
  const Vec3 fd = (plus.indenter_contact_force - minus.indenter_contact_force) / (2 * h);
  EXPECT_LT((fd - K.col(0)).norm(), 2e-5 * max_abs(K)) << "K e_x " << K.col(0).transpose() << ", finite difference "
                                                       << fd.transpose();
}

TEST(ContactStiffness, LinearFemMatchesFiniteDifferencesOfHeldStaticSolves) {
  Site t = site(kFemCube, 0.07, 0.03, 0.03);
  ASSERT_TRUE(t.local.converged);
  ASSERT_GE(t.local.active_count, 2);
  EXPECT_GT(std::abs(t.local.stiffness(0, 2)), 0.1 * std::abs(t.local.stiffness(2, 2)));
  expect_matches_finite_difference(t.setup, t.state, t.local);
}

TEST(ContactStiffness, LinearisationErrorIsSecondOrder) {
  Site t = site(kMlsCube, 0.07, 0.03, 0.03);
  const LocalContactModel& lm = t.local;
  const Vec3 u = Vec3(1.0, -2.0, -3.0).normalized();
  double errors[3];
  const double steps[3] = {0.8, 0.4, 0.2};
  for (int k = 0; k < 3; ++k) {
    const Vec3 dx = steps[k] * lm.valid_radius * u;
    const State moved = held_at(t.setup, t.state, lm.origin + dx);
    ASSERT_EQ(active_set(moved), active_set(t.state)) << "inside the validity radius the active set holds";
    errors[k] = (moved.indenter_contact_force - (lm.force + lm.stiffness * dx)).norm();
  }
  // Halving |dx| quarters the error (measured 4.0 and 4.0); at 0.8 of the radius it is
  // below 1e-3 of |F0| (measured 2.3e-4).
  EXPECT_GT(errors[0] / errors[1], 3.5);
  EXPECT_LT(errors[0] / errors[1], 4.5);
  EXPECT_GT(errors[1] / errors[2], 3.5);
  EXPECT_LT(errors[1] / errors[2], 4.5);
  std::printf("errors %g %g %g N, |F0| %g N, radius %g m\n", errors[0], errors[1], errors[2], lm.force.norm(), lm.valid_radius);
  EXPECT_LT(errors[0], 1e-2 * lm.force.norm());
}

TEST(ContactStiffness, ValidityRadiusIsWhereTheActiveSetChanges) {
  // On the MLS cube at 30 mm an active particle's multiplier sets the radius, on the FEM
  // cube at 40 mm a particle about to enter.
  int entering = 0, leaving = 0;
  for (const auto& [json, depth] : {std::pair{kMlsCube, 0.03}, std::pair{kFemCube, 0.04}}) {
    Site t = site(json, 0.07, 0.03, depth);
    const LocalContactModel& lm = t.local;
    ASSERT_GT(lm.valid_radius, 0.0);
    ASSERT_NE(lm.limited_by, LocalContactModel::Limit::no_contact);
    ASSERT_GE(lm.limiting_particle, 0);
    entering += lm.limited_by == LocalContactModel::Limit::entering;
    leaving += lm.limited_by == LocalContactModel::Limit::leaving;
    // Inside the radius, in the limiting direction, against it and up and down, the active
    // set holds.
    for (const Vec3& dir : {lm.limiting_direction, Vec3(-lm.limiting_direction), Vec3(Vec3::UnitZ()),
                            Vec3(-Vec3::UnitZ())}) {
      const State inside = held_at(t.setup, t.state, lm.origin + 0.9 * lm.valid_radius * dir);
      EXPECT_EQ(active_set(inside), active_set(t.state)) << "depth " << depth << ", 0.9 radius along " << dir.transpose();
    }
    // Just beyond it along the limiting direction the limiting particle has left or entered.
    const State beyond = held_at(t.setup, t.state, lm.origin + 1.1 * lm.valid_radius * lm.limiting_direction);
    const bool in_contact = std::find(beyond.contact_index.begin(), beyond.contact_index.end(),
                                      lm.limiting_particle) != beyond.contact_index.end();
    EXPECT_EQ(in_contact, lm.limited_by == LocalContactModel::Limit::entering)
        << "depth " << depth << ": " << to_string(lm.limited_by) << " particle " << lm.limiting_particle
        << " at 1.1 radius";
  }
  EXPECT_EQ(entering, 1);
  EXPECT_EQ(leaving, 1);
}

TEST(ContactStiffness, WithoutContactForceAndStiffnessAreZeroAndTheRadiusIsTheDistance) {
  test::Setup s = test::setup_from_json(kMlsCube);
  const Model& m = s.model;
  State st = make_state(m, s.opt);
  // The sphere touching the undeformed body at (0.07, 0.03), then moved 5 cm away from the
  // particle it touches, along their normal: the nearest particle is 5 cm off.
  const Vec3 touching(0.07, 0.03, touch_height(m, 0.07, 0.03));
  int touched = -1;
  for (int i = 0; i < m.particle_count; ++i)
    if (touched < 0 || (m.rest_position.col(i) - touching).norm() < (m.rest_position.col(touched) - touching).norm())
      touched = i;
  ASSERT_NEAR((m.rest_position.col(touched) - touching).norm(), m.indenter_radius, 1e-12);
  const double gap = 0.05;
  st.indenter_center = touching + gap * (touching - m.rest_position.col(touched)).normalized();
  st.contact_index.clear();
  st.contact_normal_force.clear();
  st.indenter_contact_force.setZero();
  ContactStiffness cs(m);
  const LocalContactModel lm = cs.evaluate(m, st);
  EXPECT_EQ(lm.active_count, 0);
  EXPECT_EQ(lm.limited_by, LocalContactModel::Limit::no_contact);
  EXPECT_TRUE(lm.stiffness.isZero(0.0));
  EXPECT_TRUE(lm.force.isZero(0.0));
  EXPECT_EQ(lm.cg_iterations, 0);
  EXPECT_NEAR(lm.valid_radius, gap, 1e-12);
  EXPECT_EQ(lm.limiting_particle, touched);
  // The static solves agree: short of the radius toward the nearest particle no contact,
  // beyond it contact.
  const State short_of = held_at(s, st, lm.origin + 0.98 * lm.valid_radius * lm.limiting_direction);
  const State past = held_at(s, st, lm.origin + 1.02 * lm.valid_radius * lm.limiting_direction);
  EXPECT_TRUE(short_of.contact_index.empty());
  EXPECT_FALSE(past.contact_index.empty());
}

// The stiffness at first touch (2.20), computed out of contact, against the static solves
// with the tool held just past the touch: with one particle touching, F(dc) = K_touch dc
// up to second order (the multiplier's normal rotation, the strain's nonlinearity), so
// the relative difference falls as the press deepens less (by about 2 when it halves).
TEST(ContactStiffness, TheStiffnessAtFirstTouchPredictsTheForceOfTheTouch) {
  test::Setup s = test::setup_from_json(kMlsCube);
  const Model& m = s.model;
  const State rest = make_state(m, s.opt);
  const Vec3 touch(0.07, 0.03, touch_height(m, 0.07, 0.03));  // one particle touches here
  int touched = 0;
  for (int i = 0; i < m.particle_count; ++i)
    if ((m.rest_position.col(i) - touch).norm() < (m.rest_position.col(touched) - touch).norm()) touched = i;
  // 2 mm away along the particle's normal (approached along another line, the normal at the
  // touch differs from the one computed here by the angle the line makes with it over R).
  State above = rest;
  above.indenter_center = touch + 2e-3 * (touch - m.rest_position.col(touched)).normalized();
  ContactStiffness plain(m), touching(m, {1e-10, 2000, true});
  const LocalContactModel without = plain.evaluate(m, above);
  EXPECT_EQ(without.touch_count, 0);
  EXPECT_TRUE(without.touch_stiffness.isZero(0.0));
  const LocalContactModel lm = touching.evaluate(m, above);
  // Again, after its first call: no allocation, and the warm start is the solution.
  const long before = g_allocations.load();
  const LocalContactModel again = touching.evaluate(m, above);
  EXPECT_EQ(g_allocations.load() - before, 0);
  EXPECT_EQ(again.cg_iterations, 0);
  EXPECT_LT(max_abs(again.touch_stiffness - lm.touch_stiffness), 1e-8 * max_abs(lm.touch_stiffness));
  ASSERT_TRUE(lm.converged);
  EXPECT_EQ(lm.active_count, 0);
  EXPECT_TRUE(lm.stiffness.isZero(0.0));  // out of contact K is zero; the touch stiffness is apart
  EXPECT_NEAR(lm.valid_radius, 2e-3, 1e-9);
  ASSERT_EQ(lm.touch_count, 1);
  EXPECT_EQ(lm.limiting_particle, touched);
  const Mat3& K = lm.touch_stiffness;
  EXPECT_LT(K(2, 2), 0.0);
  EXPECT_LT(max_abs(K - K.transpose()), 1e-6 * max_abs(K));  // (2.13) with zero multipliers
  // Pressed down and sideways from the touch point.
  const Vec3 direction = Vec3(0.3, -0.2, -1.0).normalized();
  double previous = 0.0;
  for (double depth : {2e-3, 1e-3, 5e-4}) {
    const State held = held_at(s, rest, touch + depth * direction);
    ASSERT_EQ(held.contact_index.size(), 1u) << "depth " << depth;
    EXPECT_EQ(held.contact_index[0], lm.limiting_particle);
    const Vec3 predicted = K * (depth * direction);
    const double error = (held.indenter_contact_force - predicted).norm() / held.indenter_contact_force.norm();
    std::printf("touch stiffness: %.1e m past the touch, force %.4g N, predicted %.4g N, relative difference %.2e\n",
                depth, held.indenter_contact_force.norm(), predicted.norm(), error);
    EXPECT_LT(error, 1e-2);
    if (previous > 0) {
      EXPECT_GT(previous / error, 1.6) << "the difference does not fall with the depth";
    }
    previous = error;
  }
}

// The lookahead of the stiffness at first touch (2.22): a tool coming down at v over a
// particle, with the touch stiffness to serve for T, is given the stiffness of the
// particles within d*/2 of the sphere, d* = v T / 2. Against the truth, the finite
// differences of static solves held d* past the touch, its K_zz is much nearer than the
// one particle's of (2.20); a tool that does not approach (moving sideways and away) gets
// the touch's own.
TEST(ContactStiffness, TheLookaheadTakesTheTouchStiffnessAtTheDepthItWillServe) {
  // The 8^3 cube under a 1.5 m sphere: its four lattice neighbours are 0.0275 m up the
  // sphere when a particle touches, the diagonal ones 0.055 m.
  const std::string json = std::string(kMlsCube).substr(0, std::string(kMlsCube).rfind('}')) +
                           R"(, "indenter": {"radius": 1.5}})";
  test::Setup s = test::setup_from_json(json.c_str());
  const Model& m = s.model;
  const State rest = make_state(m, s.opt);
  const double x = 1.0 / 7, y = 1.0 / 7;  // over a surface particle of the 8^3 lattice
  const Vec3 touch(x, y, touch_height(m, x, y));
  State above = rest;
  above.indenter_center = touch + Vec3(0, 0, 2e-3);
  const double v = 0.2, T = 0.8, depth = 0.5 * v * T;  // m/s, s: d* = 0.08 m
  ContactStiffness at_touch(m, {1e-10, 2000, true}), ahead(m, {1e-10, 2000, true});
  ahead.set_touch_lookahead(T);
  above.indenter_velocity = Vec3(0, 0, -v);
  const LocalContactModel one = at_touch.evaluate(m, above), five = ahead.evaluate(m, above);
  ASSERT_TRUE(one.converged && five.converged);
  EXPECT_EQ(one.touch_count, 1);
  EXPECT_EQ(five.touch_count, 5);  // the particle and its four neighbours: 0.0275 < d*/2 < 0.055
  const State held = held_at(s, rest, touch - Vec3(0, 0, depth));
  const double h = 2e-3;
  const double truth = (held_at(s, held, held.indenter_center + Vec3(0, 0, h)).indenter_contact_force[2] -
                        held_at(s, held, held.indenter_center - Vec3(0, 0, h)).indenter_contact_force[2]) /
                       (2 * h);
  std::printf("K_zz %.4g N/m at d* = %.2f m (finite differences, %zu in contact); lookahead %.4g (%d particles), "
              "at the touch %.4g\n",
              truth, depth, held.contact_index.size(), five.touch_stiffness(2, 2), five.touch_count,
              one.touch_stiffness(2, 2));
  const double error_ahead = std::abs(five.touch_stiffness(2, 2) - truth) / std::abs(truth);
  const double error_touch = std::abs(one.touch_stiffness(2, 2) - truth) / std::abs(truth);
  // Measured: 34 % against 83 %. The rule is the continuum's (Hertz: the contact reaches
  // the undeformed gap d/2); on this coarse lattice the diagonal particles, 0.055 m up,
  // are in contact too at d* (9, not 5), so the lookahead's K stays short of the truth.
  EXPECT_LT(error_ahead, 0.4);
  EXPECT_LT(error_ahead, 0.5 * error_touch);
  // Not approaching: the touch itself.
  above.indenter_velocity = Vec3(0.3, 0, 0.2);
  ahead.clear_warm_start();
  const LocalContactModel away = ahead.evaluate(m, above);
  EXPECT_EQ(away.touch_count, 1);
  EXPECT_LT(max_abs(away.touch_stiffness - one.touch_stiffness), 1e-6 * max_abs(one.touch_stiffness));
  EXPECT_THROW(ahead.set_touch_lookahead(-1.0), std::invalid_argument);
  EXPECT_THROW(ahead.set_touch_lookahead(std::nan("")), std::invalid_argument);
}

TEST(ContactStiffness, VerticalStiffnessAgreesWithTheExactLinearSolveAndHertz) {
  // The graded linear hex FEM (within 1 % of the finite-block reference): its exact linear
  // solve (5.2)-(5.3) at F +- 1 N gives dF/dd independently (vertical gaps, undeformed
  // geometry: no normals, no rotation term), and Hertz's (3.2) gives (3/2) F / d.
  const test::Setup s =
      test::setup_from(load_scene(std::string(PALPATE_SOURCE_DIR) + "/scenes/hertz_cube_graded_fem.json"));
  const Model& m = s.model;
  LinearStaticContact linear(m);
  const double F = 100.0, dF = 0.05;
  State st = make_state(m, s.opt);
  const StaticSolution up = linear.solve(F + dF), down = linear.solve(F - dF), at = linear.solve(F, &st);
  ASSERT_TRUE(up.converged && down.converged && at.converged);
  ASSERT_EQ(up.active_count, at.active_count);
  ASSERT_EQ(down.active_count, at.active_count);
  const double slope = -2 * dF / (up.indentation - down.indentation);  // dF_z/dc_z = -dF/dd
  ContactStiffness cs(m);
  const LocalContactModel lm = cs.evaluate(m, st);
  ASSERT_TRUE(lm.converged);
  const double young = 1e4, poisson = 0.3;
  const double hertz = -1.5 * F / hertz::depth(F, m.indenter_radius, young / (1 - poisson * poisson));
  // Measured: K_zz within 0.5 % of the linear solve's slope, 9 % stiffer than Hertz (the
  // finite block is stiffer than the half-space, docs/physics.md §3).
  std::printf("K_zz %.2f slope %.2f hertz %.2f (F %g d %g, %d active)\n", lm.stiffness(2, 2), slope, hertz, F, at.indentation, at.active_count);
  EXPECT_NEAR(lm.stiffness(2, 2), slope, 0.04 * std::abs(slope));
  EXPECT_NEAR(lm.stiffness(2, 2), hertz, 0.15 * std::abs(hertz));
}

TEST(ContactStiffness, WarmStartsAndNoAllocationAfterTheFirstCall) {
  Site t = site(kMlsCube, 0.07, 0.03, 0.03);
  const Model& m = t.setup.model;
  // The tool 0.1 mm further (what a 1 kHz session moves it in a tick at 0.1 m/s).
  const State next = held_at(t.setup, t.state, t.local.origin + 1e-4 * Vec3(2, -1, -2).normalized());
  ContactStiffness cold(m);
  const LocalContactModel reference = cold.evaluate(m, next);
  // From the previous state's solutions, fewer iterations and the same K.
  const long before = g_allocations.load();
  const LocalContactModel warm = t.stiffness.evaluate(m, next);
  const LocalContactModel again = t.stiffness.evaluate(m, next);
  const long allocations = g_allocations.load() - before;
  EXPECT_EQ(allocations, 0);
  EXPECT_TRUE(warm.converged);
  EXPECT_LT(warm.cg_iterations, 0.75 * reference.cg_iterations) << "cold: " << reference.cg_iterations;
  EXPECT_LT(max_abs(warm.stiffness - reference.stiffness), 1e-5 * max_abs(reference.stiffness));
  EXPECT_EQ(again.cg_iterations, 0);  // the same state again: the warm start is the solution
  // Cleared, it starts from zero.
  t.stiffness.clear_warm_start();
  EXPECT_EQ(t.stiffness.evaluate(m, next).cg_iterations, reference.cg_iterations);
}

// The server's tolerance (kRenderingStiffness, 10^-2): warm-started over a sequence of
// tool positions, as a session evaluates it, K and the valid radius stay within 10^-3
// of a 10^-12 solve of each state (whose K the finite differences above verify).
TEST(ContactStiffness, TheRenderingToleranceKeepsKWithinAThousandth) {
  Site t = site(kMlsCube, 0.07, 0.03, 0.03);
  const Model& m = t.setup.model;
  ContactStiffness rendering(m, kRenderingStiffness), tight(m, {1e-12, 2000});
  int iterations = 0, tight_iterations = 0;
  for (int k = 0; k <= 10; ++k) {  // 0.1 mm a tick, down and sideways
    const State at = held_at(t.setup, t.state, t.local.origin + 1e-4 * k * Vec3(1, 0, -2).normalized());
    const LocalContactModel served = rendering.evaluate(m, at);
    tight.clear_warm_start();
    const LocalContactModel exact = tight.evaluate(m, at);
    ASSERT_TRUE(served.converged && exact.converged) << "tick " << k;
    ASSERT_EQ(served.active_count, exact.active_count);
    EXPECT_LT(max_abs(served.stiffness - exact.stiffness), 1e-3 * max_abs(exact.stiffness)) << "tick " << k;
    EXPECT_NEAR(served.valid_radius, exact.valid_radius, 1e-3 * exact.valid_radius) << "tick " << k;
    if (k > 0) iterations += served.cg_iterations, tight_iterations += exact.cg_iterations;
  }
  std::printf("10 warm-started evaluations: %d CG iterations at the renderer's tolerance, %d from zero at 1e-12\n", iterations,
              tight_iterations);
  EXPECT_LT(iterations, tight_iterations / 4);
}

TEST(ContactStiffness, ConvergedFlagIsHonest) {
  Site t = site(kMlsCube, 0.0, 0.0, 0.03);
  const Model& m = t.setup.model;
  ContactStiffness capped(m, {1e-6, 3});
  const LocalContactModel few = capped.evaluate(m, t.state);
  EXPECT_FALSE(few.converged);
  EXPECT_EQ(few.cg_iterations, 9);
  // Converged at 1e-6, K is within 1e-5 of the one at 1e-12.
  ContactStiffness tight(m, {1e-12, 2000});
  const LocalContactModel exact = tight.evaluate(m, t.state);
  ASSERT_TRUE(t.local.converged);
  ASSERT_TRUE(exact.converged);
  EXPECT_LT(max_abs(t.local.stiffness - exact.stiffness), 1e-5 * max_abs(exact.stiffness));
}

TEST(ContactStiffness, RefusesBadSettingsAndAStateOfAnotherModel) {
  const test::Setup s = test::setup_from_json(kFemCube);
  EXPECT_THROW(ContactStiffness(s.model, {0.0, 100}), std::invalid_argument);
  EXPECT_THROW(ContactStiffness(s.model, {1e-6, 0}), std::invalid_argument);
  ContactStiffness cs(s.model);
  State bad = make_state(s.model, s.opt);
  bad.contact_index = {0};  // node 0 is a fixed bottom corner: it never touches the tool
  bad.contact_normal_force = {1.0};
  EXPECT_THROW(cs.evaluate(s.model, bad), std::invalid_argument);
  bad.contact_index = {300, 301};  // two indices, one force
  EXPECT_THROW(cs.evaluate(s.model, bad), std::invalid_argument);
  const test::Setup small = test::setup_from_json(R"({"body": {"distribution": {"type": "grid", "per_edge": 5}}})");
  EXPECT_THROW(cs.evaluate(small.model, make_state(small.model, small.opt)), std::invalid_argument);
}


// The coarse correction of the preconditioner (2.21) changes how fast the solves converge,
// not what they converge to: on a graded 11^3 cloud (a 4^3 coarse lattice) pressed at an
// off-centre site, K at 1e-10 with and without it agrees to 1e-8 of its largest entry,
// and from zero it needs fewer iterations at the renderer's tolerance and at 1e-6 (a
// coarse operator that is not T^T K T, or an interpolation that misses particles, gives
// no gain or diverges). On a uniform 12^3 cloud it gains little (51 -> 49 iterations at
// 1e-2): there block Jacobi already follows the spacing.
TEST(ContactStiffness, TheCoarseCorrectionCutsIterationsAndLeavesKUnchanged) {
  const std::string cube = R"({"body": {"distribution": {"type": "graded_grid", "per_edge": 11, "first_spacing": 0.05}},
    "mls": {"neighbors": 18, "support_factor": 1.05, "support_rule": "kth_distance", "volumes": "lattice"},
    "material": {"law": "corotational"},
    "integrator": {"type": "symplectic_euler", "dt": 0.001, "damping": 10}})";
  Site t = site(cube.c_str(), 0.07, 0.03, 0.03);
  const Model& m = t.setup.model;
  ASSERT_GT(t.local.active_count, 0);
  ContactStiffness jacobi(m, {1e-10, 20000, false, 0}), coarse(m, {1e-10, 20000, false, 4});
  EXPECT_EQ(jacobi.coarse_lattice(), Eigen::Vector3i(0, 0, 0));
  EXPECT_EQ(coarse.coarse_lattice(), Eigen::Vector3i(4, 4, 4));
  // The default asks for 6 per axis, at most a third of the cloud's 11: 4.
  EXPECT_EQ(ContactStiffness(m).coarse_lattice(), Eigen::Vector3i(4, 4, 4));
  const LocalContactModel a = jacobi.evaluate(m, t.state), b = coarse.evaluate(m, t.state);
  ASSERT_TRUE(a.converged && b.converged);
  EXPECT_LT(max_abs(a.stiffness - b.stiffness), 1e-8 * max_abs(a.stiffness)) << a.stiffness << "\n" << b.stiffness;
  for (double tolerance : {1e-2, 1e-6}) {
    ContactStiffness j(m, {tolerance, 20000, false, 0}), c(m, {tolerance, 20000, false, 4});
    const int without = j.evaluate(m, t.state).cg_iterations, with = c.evaluate(m, t.state).cg_iterations;
    std::printf("tolerance %g: %d CG iterations with block Jacobi, %d with the coarse correction\n", tolerance,
                without, with);
    EXPECT_LT(with, 0.7 * without) << "tolerance " << tolerance;
  }
  EXPECT_THROW(ContactStiffness(m, {1e-6, 100, false, 1}), std::invalid_argument);
  EXPECT_THROW(ContactStiffness(m, {1e-6, 100, false, 13}), std::invalid_argument);
}


// An unchanged state (a tool held still, a body at rest) gets the last result again
// without a tangent sweep, and allocates nothing; a particle moved by 10^-3 of the
// smallest spacing, a changed multiplier or a cleared warm start make it evaluate anew,
// and that result equals a fresh instance's.
TEST(ContactStiffness, AnUnchangedStateReusesTheLastResult) {
  Site t = site(kMlsCube, 0.07, 0.03, 0.03);
  const Model& m = t.setup.model;
  ContactStiffness cs(m, kRenderingStiffness);
  const LocalContactModel first = cs.evaluate(m, t.state);
  EXPECT_FALSE(first.reused);
  State later = t.state;
  later.tick += 7;
  later.position.col(0) += Vec3(0, 0, 1e-7 * m.min_spacing);  // below the 1e-6 tolerance
  const long before = g_allocations.load();
  const LocalContactModel again = cs.evaluate(m, later);
  EXPECT_EQ(g_allocations.load() - before, 0);
  EXPECT_TRUE(again.reused);
  EXPECT_EQ(again.tick, later.tick);
  EXPECT_EQ(again.cg_iterations, 0);
  EXPECT_EQ(again.stiffness, first.stiffness);
  EXPECT_EQ(again.valid_radius, first.valid_radius);
  auto expect_anew = [&](const State& s, const char* what) {
    SCOPED_TRACE(what);
    const LocalContactModel r = cs.evaluate(m, s);
    EXPECT_FALSE(r.reused);
    ContactStiffness fresh(m, kRenderingStiffness);
    const LocalContactModel f = fresh.evaluate(m, s);
    EXPECT_LT(max_abs(r.stiffness - f.stiffness), 1e-2 * max_abs(f.stiffness));
  };
  State moved = t.state;
  const int free_particle = t.state.contact_index[0];
  moved.position.col(free_particle) += Vec3(1e-3 * m.min_spacing, 0, 0);
  expect_anew(moved, "a particle moved");
  State pressed = t.state;
  pressed.contact_normal_force[0] *= 1.01;
  expect_anew(pressed, "a multiplier changed");
  cs.clear_warm_start();
  expect_anew(pressed, "the warm start cleared");
  // Out of contact, the same holds for the stiffness at first touch.
  State above = make_state(m, t.setup.opt);
  above.indenter_center = Vec3(0.07, 0.03, touch_height(m, 0.07, 0.03) + 1e-3);
  ContactStiffness touching(m, kRenderingStiffness);
  const LocalContactModel out_of_contact = touching.evaluate(m, above);
  ASSERT_GT(out_of_contact.touch_count, 0);
  const LocalContactModel out_again = touching.evaluate(m, above);
  EXPECT_TRUE(out_again.reused);
  EXPECT_EQ(out_again.touch_stiffness, out_of_contact.touch_stiffness);
  // Approaching with a lookahead changes the touch's depth: anew.
  touching.set_touch_lookahead(0.5);
  above.indenter_velocity = Vec3(0, 0, -0.05);
  EXPECT_FALSE(touching.evaluate(m, above).reused);
}

}  // namespace
}  // namespace palpate
