// The rendered force's local model (server/local_model.h) against the quasi-static
// equilibrium it linearises, solved directly: a tool between the virtual coupling
// k (x_d - c) and a contact force F_c(c) that is not linear (a Hertz-like normal
// law and a lateral spring), at rest where k (x_d - c) + F_c(c) = 0.
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "core/contact_stiffness.h"
#include "core/state.h"
#include "server/local_model.h"
#include "test_util.h"

namespace {

using palpate::CouplingOptions;
using palpate::Mat3;
using palpate::Vec3;
using palpate::server::LocalModel;
using palpate::server::render_model;

// A contact force on the tool at c, conservative like the elastic contact (F = -dPi/dc,
// so K is symmetric; docs/physics.md (2.13)): the surface z = 0 pushes up with d^1.5
// (Hertz: F ~ d^(3/2), d = -c_z) and holds x, y with a stiffness growing with the depth,
//   Pi = 400 d^2.5 + 20 d x^2 + 7.5 d y^2   (convex where the tool presses: K negative definite).
Vec3 contact_force(const Vec3& c) {
  const double d = std::max(0.0, -c[2]);
  const double touching = d > 0.0 ? 1.0 : 0.0;
  return Vec3(-40.0 * d * c[0], -15.0 * d * c[1],
              1e3 * std::pow(d, 1.5) + touching * (20.0 * c[0] * c[0] + 7.5 * c[1] * c[1]));
}
Mat3 contact_stiffness(const Vec3& c) {  // dF/dc = -Hessian(Pi), by hand
  const double d = std::max(0.0, -c[2]);
  Mat3 K = Mat3::Zero();
  if (d == 0.0) return K;
  K(0, 0) = -40.0 * d;
  K(0, 2) = K(2, 0) = 40.0 * c[0];
  K(1, 1) = -15.0 * d;
  K(1, 2) = K(2, 1) = 15.0 * c[1];
  K(2, 2) = -1.5e3 * std::sqrt(d);
  return K;
}

// The tool's rest position for the device at x_d (Newton on the force balance).
Vec3 rest_tool(const Vec3& xd, double k) {
  Vec3 c = xd;
  for (int it = 0; it < 100; ++it) {
    const Vec3 r = k * (xd - c) + contact_force(c);
    const Mat3 J = -k * Mat3::Identity() + contact_stiffness(c);
    c -= J.lu().solve(r);
  }
  return c;
}

Vec3 rendered(const Vec3& xd, double k) { return -k * (xd - rest_tool(xd, k)); }

TEST(LocalModel, RenderStiffnessIsTheCouplingAndTheContactInSeries) {
  const double k = 300.0;
  const Vec3 xd(0.004, -0.003, -0.02);
  const Vec3 c = rest_tool(xd, k);
  LocalModel contact;
  contact.origin = c;
  contact.force = contact_force(c);
  contact.stiffness = contact_stiffness(c);
  const LocalModel r = render_model(contact, true, xd, rendered(xd, k), CouplingOptions{k, 5.0}, 0.0);
  EXPECT_EQ(r.origin, xd);
  // Central differences of the exact equilibrium, column by column.
  const double h = 1e-6;
  for (int j = 0; j < 3; ++j) {
    const Vec3 e = Vec3::Unit(j) * h;
    const Vec3 column = (rendered(xd + e, k) - rendered(xd - e, k)) / (2 * h);
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(r.stiffness(i, j), column[i], 1e-6 * r.stiffness.norm()) << i << "," << j;
  }
  // The device feels less than either spring alone along z (series), and the model
  // predicts a small move to second order.
  EXPECT_LT(std::abs(r.stiffness(2, 2)), std::min(k, std::abs(contact.stiffness(2, 2))));
  const Vec3 dx(2e-4, -1e-4, -3e-4);
  const Vec3 predicted = r.force + r.stiffness * dx;
  const Vec3 predicted_half = r.force + r.stiffness * (dx / 2);
  const double e1 = (predicted - rendered(xd + dx, k)).norm();
  const double e2 = (predicted_half - rendered(xd + dx / 2, k)).norm();
  EXPECT_NEAR(e1 / e2, 4.0, 0.5);
}

TEST(LocalModel, TheRenderedStiffnessIsPassive) {
  // A contact stiffness with a positive eigenvalue along x (a sphere pushed sideways
  // off a particle) and a small asymmetry.
  Mat3 K;
  K << 50.0, 1.0, 0.0,  //
      0.0, -200.0, 0.0,  //
      0.0, 0.0, -3000.0;
  const Mat3 P = palpate::server::passive_stiffness(K);
  EXPECT_TRUE(P.isApprox(P.transpose(), 1e-14));
  const Eigen::SelfAdjointEigenSolver<Mat3> eigen(P);
  EXPECT_LE(eigen.eigenvalues().maxCoeff(), 1e-9);
  EXPECT_NEAR(P(2, 2), -3000.0, 1e-9);  // the restoring directions are kept
  EXPECT_NEAR(P(1, 1), -200.0, 0.01);
  // A passive K is left as it is.
  const Mat3 N = -Mat3::Identity() * 7.0;
  EXPECT_TRUE(palpate::server::passive_stiffness(N).isApprox(N, 1e-14));
  LocalModel contact;
  contact.stiffness = K;
  const LocalModel r = render_model(contact, false, Vec3::Zero(), Vec3::Zero(), CouplingOptions{}, 0.0);
  EXPECT_TRUE(r.stiffness.isApprox(P, 1e-12));
}

TEST(LocalModel, ForceModeRendersTheContactModelItself) {
  LocalModel contact;
  contact.origin = Vec3(1, 2, 3);
  contact.force = Vec3(0, 0, 4);
  contact.stiffness = -Mat3::Identity() * 7.0;
  contact.valid_radius = 0.01;
  contact.stiffness_tick = 42;
  LocalModel r = render_model(contact, false, Vec3(9, 9, 9), Vec3(5, 5, 5), CouplingOptions{100.0, 1.0}, 0.001);
  EXPECT_EQ(r.origin, contact.origin);
  EXPECT_EQ(r.valid_radius, 0.01);  // above the floor: kept
  contact.valid_radius = 1e-6;      // in contact, below the floor: raised to it
  EXPECT_EQ(render_model(contact, false, Vec3(), Vec3(), CouplingOptions{}, 0.001).valid_radius, 0.001);
  contact.force.setZero();          // out of contact: the distance to the body, never raised
  EXPECT_EQ(render_model(contact, false, Vec3(), Vec3(), CouplingOptions{}, 0.001).valid_radius, 1e-6);
  contact.force = Vec3(0, 0, 4);
  contact.valid_radius = 0.01;
  EXPECT_EQ(r.force, contact.force);
  EXPECT_EQ(r.stiffness, contact.stiffness);
  EXPECT_EQ(r.stiffness_tick, 42);
}

}  // namespace

// contact_model_now's choice of stiffness (docs/physics.md (2.20)): a stiffness computed out
// of contact serves once the tool touches only through its stiffness at first touch; one
// computed in contact serves while the tool still touches.
TEST(LocalModel, TheStiffnessAtFirstTouchServesUntilOneInContactArrives) {
  using palpate::LocalContactModel;
  using palpate::server::contact_model_now;
  LocalContactModel before;  // out of contact, 10 mm above the body
  before.tick = 5;
  before.origin = Vec3(0, 0, 0.01);
  before.valid_radius = 0.01;
  before.touch_count = 1;
  before.touch_stiffness = Vec3(-1.0, -2.0, -300.0).asDiagonal();
  palpate::State now;  // touching, 1 mm in
  now.indenter_center = Vec3(0, 0, -0.001);
  now.indenter_contact_force = Vec3(0, 0, 0.3);
  now.contact_index = {7};
  now.contact_normal_force = {0.3};
  LocalModel m = contact_model_now(now, before);
  EXPECT_EQ(m.stiffness, before.touch_stiffness);
  EXPECT_EQ(m.stiffness_tick, 5);
  EXPECT_EQ(m.valid_radius, 0.0);  // render_model's floor applies in contact
  EXPECT_EQ(m.force, now.indenter_contact_force);
  // Without a stiffness at first touch: none.
  LocalContactModel plain = before;
  plain.touch_count = 0;
  plain.touch_stiffness.setZero();
  EXPECT_TRUE(contact_model_now(now, plain).stiffness.isZero(0.0));
  // Still out of contact: no stiffness; the radius shrinks by the tool's travel.
  palpate::State approaching;
  approaching.indenter_center = Vec3(0, 0, 0.004);
  m = contact_model_now(approaching, before);
  EXPECT_TRUE(m.stiffness.isZero(0.0));
  EXPECT_NEAR(m.valid_radius, 0.004, 1e-15);
  // Computed in contact, the tool has left: none.
  LocalContactModel in_contact = before;
  in_contact.active_count = 3;
  in_contact.stiffness = Vec3(-5.0, -5.0, -500.0).asDiagonal();
  EXPECT_TRUE(contact_model_now(approaching, in_contact).stiffness.isZero(0.0));
  EXPECT_EQ(contact_model_now(now, in_contact).stiffness, in_contact.stiffness);
}

// A real-time source (its worker thread) primed with the start state holds that state's
// evaluation at once, the one ContactStiffness gives with the renderer's settings; a
// headless one is left to its first offer.
TEST(StiffnessSource, PrimingGivesTheFirstFramesAStiffness) {
  const palpate::test::Setup s = palpate::test::setup_from_json(
      R"({"body": {"distribution": {"type": "grid", "per_edge": 6}}, "integrator": {"type": "symplectic_euler", "dt": 0.001}})");
  const palpate::State start = palpate::make_state(s.model, s.opt);
  palpate::server::StiffnessSource threaded(s.model, true), headless(s.model, false);
  EXPECT_EQ(threaded.newest().tick, -1);
  threaded.prime(start);
  headless.prime(start);
  EXPECT_EQ(headless.newest().tick, -1);
  EXPECT_EQ(headless.evaluations(), 0u);
  ASSERT_EQ(threaded.newest().tick, start.tick);
  EXPECT_EQ(threaded.evaluations(), 1u);
  palpate::ContactStiffness direct(s.model, palpate::kRenderingStiffness);
  const palpate::LocalContactModel expected = direct.evaluate(s.model, start);
  EXPECT_EQ(threaded.newest().touch_count, expected.touch_count);
  EXPECT_GT(expected.touch_count, 0);  // the tool starts touching the lattice's top
  EXPECT_EQ(threaded.newest().touch_stiffness, expected.touch_stiffness);
}

