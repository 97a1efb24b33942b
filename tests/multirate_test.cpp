// Multirate haptics (server/haptic_loop.h): the force of a local model (LocalModel::force_at,
// protocol/local_model.h), the render tick's choice of device position, the renderer thread,
// the loop's watchdog (server/deadlines.h), and the multirate force against the same scene
// stepped at the haptic rate (bench/multirate_study.h) on a small cloud.
#include <sys/eventfd.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <thread>

#include <gtest/gtest.h>

#include "bench/multirate_study.h"
#include "server/deadlines.h"
#include "server/haptic_loop.h"

namespace palpate::server {
namespace {

LocalModel example_model() {
  LocalModel m;
  m.origin = {0.1, 0.2, 0.3};
  m.force = {1.0, -2.0, 30.0};
  m.stiffness << -100, 10, 0, 10, -200, 0, 0, 0, -1000;
  m.valid_radius = 0.01;
  m.stiffness_tick = 5;
  return m;
}

TEST(LocalModelForceAt, IsTheLinearModelWithinItsRadius) {
  const LocalModel m = example_model();
  EXPECT_TRUE(m.force_at(m.origin, 0.0).isApprox(m.force));
  const Vec3 d(0.001, -0.002, 0.003);  // |d| < 0.01
  const Vec3 expected(1.0 + (-100 * 0.001 + 10 * -0.002), -2.0 + (10 * 0.001 - 200 * -0.002), 30.0 - 1000 * 0.003);
  EXPECT_TRUE(m.force_at(m.origin + d, 0.0).isApprox(expected, 1e-14));
}

TEST(LocalModelForceAt, HoldsTheForceOnTheRadiusBeyondIt) {
  const LocalModel m = example_model();
  const Vec3 far = m.origin + Vec3(0, 0, 0.05);  // 5 radii below
  const Vec3 on_radius = m.origin + Vec3(0, 0, 0.01);
  EXPECT_TRUE(m.force_at(far, 0.0).isApprox(m.force_at(on_radius, 0.0), 1e-14));
  EXPECT_NEAR(m.force_at(far, 0.0)[2], 30.0 - 10.0, 1e-12);
}

TEST(LocalModelForceAt, WithoutAStiffnessOrRadiusHoldsTheForce) {
  LocalModel m = example_model();
  m.stiffness_tick = -1;
  EXPECT_TRUE(m.force_at(m.origin + Vec3(0.005, 0, 0), 0.0).isApprox(m.force));
  m = example_model();
  m.valid_radius = 0.0;
  EXPECT_TRUE(m.force_at(m.origin + Vec3(0.005, 0, 0), 0.0).isApprox(m.force));
}

TEST(LocalModelForceAt, SaturatesAtTheDevicesForceKeepingTheDirection) {
  const LocalModel m = example_model();
  bool saturated = false;
  const Vec3 f = m.force_at(m.origin, 3.0, &saturated);
  EXPECT_TRUE(saturated);
  EXPECT_NEAR(f.norm(), 3.0, 1e-12);
  EXPECT_TRUE(f.normalized().isApprox(m.force.normalized()));
  m.force_at(m.origin, 100.0, &saturated);
  EXPECT_FALSE(saturated);
}

TEST(RenderSample, RendersANewerDevicePositionAndOnlyANewerOne) {
  RenderInput in;
  in.valid = true;
  in.render_model = example_model();
  in.target = in.render_model.origin;
  in.render_force = in.render_model.force;
  in.position_mode = true;
  in.command_seq = 10;
  const Vec3 moved = in.target + Vec3(0, 0, -0.002);
  HapticSample newer = render_sample(in, {moved, 11}, 0.0);
  EXPECT_TRUE(newer.target.isApprox(moved));
  EXPECT_NEAR(newer.render_force[2], 30.0 + 2.0, 1e-12);
  EXPECT_EQ(newer.command_seq, 11u);
  HapticSample older = render_sample(in, {moved, 9}, 0.0);  // already in the step
  EXPECT_TRUE(older.target.isApprox(in.target));
  EXPECT_TRUE(older.render_force.isApprox(in.render_force));
  EXPECT_EQ(older.command_seq, 10u);
  in.position_mode = false;  // force mode: the step's force, whatever the device did
  in.force_saturated = true;  // the step clipped it: rendered as it is, and said so
  HapticSample force_mode = render_sample(in, {moved, 11}, 0.0);
  EXPECT_TRUE(force_mode.render_force.isApprox(in.render_force));
  EXPECT_TRUE(force_mode.force_saturated);
}

TEST(HapticRenderer, RendersTheNewestModelAtTheNewestDevicePosition) {
  const int fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  ASSERT_GE(fd, 0);
  {
    HapticRenderer renderer(2000.0, 0.0, 50.0, false, fd);
    RenderInput in;
    in.valid = true;
    in.render_model = example_model();
    in.target = in.render_model.origin;
    in.position_mode = true;
    in.tick = 7;
    in.command_seq = 3;
    in.publish_ns = now_ns();
    renderer.offer_model(in);
    const Vec3 moved = in.target + Vec3(0.001, 0, 0);
    renderer.offer_device(moved, 4);
    const Vec3 expected = in.render_model.force_at(moved, 0.0);
    bool seen = false;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (!seen && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      if (!renderer.samples().take()) continue;
      const HapticSample& s = renderer.samples().front();
      EXPECT_EQ(s.model_tick, 7);
      seen = s.command_seq == 4 && s.render_force.isApprox(expected, 1e-14) && s.target.isApprox(moved);
    }
    EXPECT_TRUE(seen) << "no sample rendered the new device position";
    EXPECT_GT(renderer.counters().ticks, 0);
    EXPECT_GT(renderer.counters().model_age_us.count, 0u);
  }
  close(fd);
}

// Wall-clock tests (a suite named *Timing: ctest label `timing`, docs/robustness.md).
TEST(DeadlinesTiming, TheWatchdogRestsALoopThatNeverSleeps) {
  // Every tick works 2 periods: the loop never sleeps, so within the 20 ms window it must rest.
  Deadlines d(1'000'000, 100'000, 20'000'000, 2'000'000);
  d.start();
  int rests = 0, misses = 0;
  for (int k = 0; k < 40; ++k) {
    const int64_t start = d.wait();
    while (now_ns() < start + 2'000'000) cpu_relax();
    const Deadlines::Outcome o = d.finish(start);
    rests += o.watchdog_rest;
    misses += o.missed;
  }
  EXPECT_GE(rests, 1);
  EXPECT_LE(rests, 8);  // one per window of 20 ms behind, not every tick
  EXPECT_GT(misses, 30);
}

TEST(DeadlinesTiming, ALoopInTimeNeverRests) {
  Deadlines d(2'000'000, 100'000, 20'000'000, 2'000'000);
  d.start();
  for (int k = 0; k < 30; ++k) {
    const int64_t start = d.wait();
    EXPECT_FALSE(d.finish(start).watchdog_rest);
  }
}

}  // namespace
}  // namespace palpate::server

namespace palpate::bench {
namespace {

// The multirate force against the truth (the same cloud stepped at the haptic rate): the
// 8^3 Hertz cube with symplectic Euler, the model at 4 ms, rendered at 1 kHz, along the
// palpation path in 12 s. Where the device moves into or out of the body (press, lift)
// the local model must beat the zero-order hold of the steps' forces clearly, and stay
// within a few per cent of the peak force.
TEST(Multirate, TheLocalModelBeatsTheHoldAgainstTheFineRun) {
  MultirateConfig c;
  c.scene_file = PALPATE_SOURCE_DIR "/scenes/hertz_cube.json";
  c.overrides = {{"body.distribution.per_edge", "8"}, {"integrator.type", "symplectic_euler"}};
  c.haptic_rate_hz = 1000;
  c.model_dt = 0.004;
  c.seconds = 12;
  c.stiffness_lags = {0};
  const MultirateResult r = run_multirate_study(c);
  ASSERT_GT(r.samples.size(), 11000u);
  ASSERT_GT(r.peak, 100.0);  // it pressed
  // The study's emulation of a lagging stiffness (the server's contact_model_now on the
  // frames' stiffness_source) is, at lag 0, the session's own render, to the bit.
  for (const auto& s : r.samples) {
    ASSERT_EQ(s.lagged.size(), 1u);
    ASSERT_EQ(s.lagged[0], s.multirate) << "t = " << s.t;
  }
  for (const haptic::Motion motion : {haptic::Motion::press, haptic::Motion::lift}) {
    std::vector<double> local, hold;
    for (const auto& s : r.samples)
      if (r.segments[s.segment].motion == motion) {
        local.push_back((s.multirate - s.truth).norm());
        hold.push_back((s.hold - s.truth).norm());
      }
    ASSERT_FALSE(local.empty());
    auto p99 = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      return v[static_cast<size_t>(0.99 * (v.size() - 1))];
    };
    SCOPED_TRACE(haptic::motion_name(motion));
    EXPECT_LT(p99(local), 0.7 * p99(hold));
    EXPECT_LT(p99(local), 0.03 * r.peak);
  }
}

}  // namespace
}  // namespace palpate::bench
