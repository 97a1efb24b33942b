// The client side of haptic rendering (clients/haptic.h): the palpation path, the force from
// a local model (LocalModel::force_at, docs/protocol.md (P.0)), the latency matcher and the
// rendering error, each against values worked out by hand or an independent evaluation.
#include <gtest/gtest.h>

#include <cmath>

#include "cli/statistics.h"
#include "clients/haptic.h"

namespace {

using palpate::haptic::Geometry;
using palpate::haptic::LatencyTracker;
using palpate::haptic::LocalModel;
using palpate::haptic::Motion;
using palpate::haptic::PalpationPath;
using palpate::haptic::RenderingError;
using palpate::haptic::V3;

// hertz_cube's geometry: the box [-1, 1]^2 x [-2, 0], R = 0.5, workspace grown by 2 R.
Geometry cube() {
  Geometry g;
  g.box_min = {-1, -1, -2};
  g.box_max = {1, 1, 0};
  g.radius = 0.5;
  g.touch_height = 0.5;
  g.workspace_min = {-2, -2, -3};
  g.workspace_max = {2, 2, 1};
  return g;
}

double distance(const V3& a, const V3& b) { return palpate::haptic::norm({a[0] - b[0], a[1] - b[1], a[2] - b[2]}); }

TEST(PalpationPath, SegmentsInOrderContiguousAndCoveringTheDuration) {
  const PalpationPath path(cube(), {0, 0, 0.5}, 11.5);
  const Motion expected[] = {Motion::approach, Motion::press, Motion::hold, Motion::slide, Motion::lift,
                             Motion::move,     Motion::press, Motion::hold, Motion::lift};
  ASSERT_EQ(path.segments().size(), std::size(expected));
  double t = 0;
  for (size_t k = 0; k < path.segments().size(); ++k) {
    const auto& s = path.segments()[k];
    EXPECT_EQ(s.motion, expected[k]) << s.label;
    EXPECT_EQ(s.t0, t) << s.label;
    EXPECT_GT(s.t1, s.t0) << s.label;
    if (k > 0) {  // each starts where the last ended
      EXPECT_EQ(s.p0, path.segments()[k - 1].p1) << s.label;
    }
    EXPECT_EQ(path.segment_at(0.5 * (s.t0 + s.t1)), k);
    t = s.t1;
  }
  EXPECT_EQ(t, 11.5);
  EXPECT_EQ(path.segments()[3].label, "slide A-B");
  EXPECT_EQ(path.segment_at(-1.0), 0u);  // clamped
  EXPECT_EQ(path.segment_at(100.0), path.segments().size() - 1);
}

TEST(PalpationPath, DepthSitesAndStartAsAsked) {
  const Geometry g = cube();
  const V3 start = {0.1, -0.2, 0.45};
  for (double depth : {0.0, 0.05}) {
    const PalpationPath path(g, start, 6.0, depth);
    const double d = depth > 0 ? depth : g.radius / 5;  // default R/5
    EXPECT_DOUBLE_EQ(path.depth(), d);
    EXPECT_DOUBLE_EQ(path.press_z(), g.touch_height - d);
    EXPECT_DOUBLE_EQ(path.air_z(), g.touch_height + d);
    EXPECT_EQ(path.position(0.0), start);
    for (const auto& s : path.segments()) {
      const V3 mid = path.position(0.5 * (s.t0 + s.t1));
      if (s.motion == Motion::hold || s.motion == Motion::slide) {
        EXPECT_DOUBLE_EQ(mid[2], g.touch_height - d) << s.label;
      }
      if (s.motion == Motion::move) {
        EXPECT_DOUBLE_EQ(mid[2], g.touch_height + d) << s.label;
      }
    }
    // Sites: A = centre - w/4 in x, B = centre + w/4 in x, C = centre + h/4 in y (w = h = 2).
    const auto& seg = path.segments();
    EXPECT_EQ(seg[2].p0, (V3{-0.5, 0, g.touch_height - d}));  // hold A
    EXPECT_EQ(seg[3].p1, (V3{0.5, 0, g.touch_height - d}));   // slide to B
    EXPECT_EQ(seg[7].p0, (V3{0, 0.5, g.touch_height - d}));   // hold C
    EXPECT_EQ(path.position(path.duration()), (V3{0, 0.5, g.touch_height + d}));  // lifted at the end
  }
}

TEST(PalpationPath, ContinuousC1AndInsideTheWorkspace) {
  Geometry g = cube();
  g.workspace_min = {-0.6, -2, 0.45};  // cuts site A and the pressing depth: clamped
  const double duration = 2.0;
  const PalpationPath path(g, {0, 0, 0.5}, duration);
  EXPECT_DOUBLE_EQ(path.press_z(), 0.45);
  // The largest speed of a cosine ramp over a segment of length L and time T is pi L / (2 T).
  double vmax = 0;
  for (const auto& s : path.segments()) vmax = std::max(vmax, M_PI * distance(s.p0, s.p1) / (2 * (s.t1 - s.t0)));
  const double dt = 1e-5;
  V3 previous = path.position(0);
  for (double t = dt; t <= duration; t += dt) {
    const V3 p = path.position(t);
    for (int i = 0; i < 3; ++i) {
      EXPECT_GE(p[i], g.workspace_min[i]);
      EXPECT_LE(p[i], g.workspace_max[i]);
    }
    ASSERT_LE(distance(p, previous), vmax * dt * (1 + 1e-6)) << "a jump at t = " << t;
    previous = p;
  }
  // C1: the velocity (central difference) is zero at every segment boundary.
  const double h = 1e-6;
  for (const auto& s : path.segments()) {
    const V3 a = path.position(s.t1 - h), b = path.position(s.t1 + h), c = path.position(s.t1);
    EXPECT_LT(distance(a, c) / h, 1e-4 * std::max(vmax, 1.0)) << s.label;
    if (s.t1 < duration) {
      EXPECT_LT(distance(b, c) / h, 1e-4 * std::max(vmax, 1.0)) << s.label;
    }
  }
}

TEST(PalpationPath, RefusesBadParameters) {
  EXPECT_THROW(PalpationPath(cube(), {0, 0, 0.5}, 0.0), std::invalid_argument);
  EXPECT_THROW(PalpationPath(cube(), {0, 0, 0.5}, NAN), std::invalid_argument);
  EXPECT_THROW(PalpationPath(cube(), {0, 0, 0.5}, 1.0, -0.1), std::invalid_argument);
  Geometry g = cube();
  g.workspace_min[2] = 5;  // empty workspace
  EXPECT_THROW(PalpationPath(g, {0, 0, 0.5}, 1.0), std::invalid_argument);
}

// The reports' percentiles (cli::quantile, nearest rank): a sample of the sample, never
// an interpolation; q = 0 the smallest, q = 1 the largest.
TEST(Percentiles, NearestRankOfTheSample) {
  std::vector<double> v;
  for (int k = 100; k >= 1; --k) v.push_back(k);  // 100 .. 1: unsorted
  const palpate::haptic::Percentiles p = palpate::haptic::percentiles(v);
  EXPECT_EQ(p.count, 100u);
  EXPECT_EQ(p.p50, 50.0);
  EXPECT_EQ(p.p99, 99.0);
  EXPECT_EQ(p.max, 100.0);
  EXPECT_EQ(v.front(), 100.0);  // the caller's sample is left as it was
  EXPECT_EQ(palpate::cli::quantile({3, 1, 2}, 0.0), 1.0);
  EXPECT_EQ(palpate::cli::quantile({1, 2}, 0.5), 1.0);  // not the mean of the two (cli::median)
  EXPECT_EQ(palpate::cli::quantile({1, 2}, 0.51), 2.0);
  EXPECT_TRUE(std::isnan(palpate::haptic::percentiles({}).p99));
}

LocalModel model() {
  LocalModel m;
  m.origin = {1, 2, 3};
  m.force = {0.5, -1, 10};
  m.stiffness = {-100, 0, 10, 0, -200, 0, 5, 0, -1000};
  m.valid_radius = 0.01;
  m.stiffness_tick = 7;
  return m;
}

TEST(Render, LinearInsideTheValidRadius) {
  const LocalModel m = model();
  const V3 x = {1.003, 1.998, 2.995};  // |x - x0| = 0.0062 < 0.01
  const V3 f = m.force_at(x, 0);
  // F0 + K (x - x0), worked out: dx = (0.003, -0.002, -0.005).
  EXPECT_NEAR(f[0], 0.5 - 100 * 0.003 + 10 * -0.005, 1e-12);
  EXPECT_NEAR(f[1], -1 - 200 * -0.002, 1e-12);
  EXPECT_NEAR(f[2], 10 + 5 * 0.003 - 1000 * -0.005, 1e-12);
}

TEST(Render, ClipsToTheValidRadiusAndHoldsWithoutOne) {
  LocalModel m = model();
  const V3 far = {1, 2, 3 - 0.5};  // 0.5 m below the origin: clipped to 0.01 m
  const V3 f = m.force_at(far, 0);
  const V3 at_radius = m.force_at({1, 2, 3 - 0.01}, 0);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(f[i], at_radius[i], 1e-12);
  EXPECT_NEAR(f[2], 10 + 1000 * 0.01, 1e-12);
  m.valid_radius = 0;  // do not extrapolate: the zero-order hold
  EXPECT_EQ(m.force_at(far, 0), m.force);
  m = model();
  m.stiffness_tick = -1;  // no stiffness computed yet
  EXPECT_EQ(m.force_at({1.001, 2, 3}, 0), m.force);
}

TEST(Render, SaturatesAtTheDeviceForceKeepingTheDirection) {
  const LocalModel m = model();
  const V3 x = {1, 2, 2.995};
  const V3 free = m.force_at(x, 0);
  ASSERT_GT(palpate::haptic::norm(free), 5.0);
  const V3 f = m.force_at(x, 5.0);
  EXPECT_NEAR(palpate::haptic::norm(f), 5.0, 1e-12);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(f[i] / 5.0, free[i] / palpate::haptic::norm(free), 1e-12);
  EXPECT_EQ(m.force_at(x, 1e6), free);  // below the limit: untouched
}

TEST(LatencyTracker, PairsSeqsWithTheFirstFrameReflectingThem) {
  LatencyTracker l;
  l.on_send(0.0);         // seq 5
  l.on_send(1.0);         // seq 6 (its frame comes before its reply)
  l.on_send(2.0);         // refused
  l.on_send(3.0);         // seq 7
  l.on_reply(5);
  l.on_frame(4, 0.5);     // an older command: resolves nothing
  EXPECT_TRUE(l.latencies().empty());
  l.on_frame(5, 0.75);    // seq 5: 0.75 s
  ASSERT_EQ(l.latencies().size(), 1u);
  EXPECT_DOUBLE_EQ(l.latencies()[0], 0.75);
  l.on_frame(6, 1.5);     // reflects seq 6, whose reply has not come yet
  l.on_frame(6, 1.6);
  l.on_reply(6);          // resolved from the frame already seen: 0.5 s
  ASSERT_EQ(l.latencies().size(), 2u);
  EXPECT_DOUBLE_EQ(l.latencies()[1], 0.5);
  l.on_refused();         // the third send
  EXPECT_EQ(l.refused(), 1u);
  EXPECT_EQ(l.pending(), 1u);
  l.on_frame(6, 3.5);
  l.on_reply(7);
  l.on_frame(9, 4.25);    // a frame that skipped seq 7 and 8 still reflects 7: 1.25 s
  ASSERT_EQ(l.latencies().size(), 3u);
  EXPECT_DOUBLE_EQ(l.latencies()[2], 1.25);
  EXPECT_EQ(l.pending(), 0u);
  EXPECT_THROW(l.on_reply(10), std::logic_error);  // a reply without a send
}

TEST(LatencyTracker, AnOlderCommandsFrameDoesNotResolveALaterSend) {
  LatencyTracker l;
  l.on_send(0.0);
  l.on_frame(3, 0.2);  // seq 3 (the reply below), seen before the second send
  l.on_send(0.4);
  l.on_reply(3);
  l.on_frame(3, 0.6);
  l.on_reply(4);
  ASSERT_EQ(l.latencies().size(), 1u);
  EXPECT_DOUBLE_EQ(l.latencies()[0], 0.2);
  EXPECT_EQ(l.pending(), 1u);
  l.on_frame(4, 0.9);
  ASSERT_EQ(l.latencies().size(), 2u);
  EXPECT_DOUBLE_EQ(l.latencies()[1], 0.5);
}

TEST(LatencyTracker, KeepsALongRunBounded) {
  LatencyTracker l;
  for (uint64_t k = 1; k <= 20000; ++k) {  // each reply before its frame, one tick later
    l.on_send(1e-3 * k);
    l.on_reply(k);
    l.on_frame(k, 1e-3 * k + 4e-4);
  }
  ASSERT_EQ(l.latencies().size(), 20000u);
  for (double x : l.latencies()) ASSERT_NEAR(x, 4e-4, 1e-12);
  EXPECT_EQ(l.pending(), 0u);
}

RenderingError::Frame frame(int64_t tick, const V3& x, const LocalModel& law) {
  // A frame of a body whose render force is exactly linear in the target: the law at x.
  RenderingError::Frame f;
  f.tick = tick;
  f.position_mode = true;
  f.target = x;
  f.render_force = law.force_at(x, 0);
  f.render_model = law;
  f.render_model.origin = x;
  f.render_model.force = f.render_force;
  return f;
}

TEST(RenderingError, TheLocalModelOfALinearLawIsExactAndTheHoldIsNot) {
  LocalModel law = model();
  law.valid_radius = 1.0;
  RenderingError e(2, 0);
  for (int k = 0; k < 10; ++k) e.on_frame(frame(k, {1, 2, 3 - 1e-4 * k}, law), k < 5 ? 0 : 1);
  EXPECT_EQ(e.compared(), 9u);
  const auto all = e.overall();
  EXPECT_LT(all.local.max, 1e-12);
  // The hold misses by |K dx| per tick: dx = (0, 0, -1e-4): (10, 0, 1000) * 1e-4... = |(-1e-3, 0, 0.1)|.
  EXPECT_NEAR(all.hold.p50, std::hypot(1e-3, 0.1), 1e-12);
  EXPECT_NEAR(all.hold.max, std::hypot(1e-3, 0.1), 1e-12);
  EXPECT_EQ(e.segment(0).local.count, 4u);
  EXPECT_EQ(e.segment(1).local.count, 5u);
  EXPECT_NEAR(e.peak_force(), palpate::haptic::norm(law.force_at({1, 2, 3 - 9e-4}, 0)), 1e-12);
}

TEST(RenderingError, ComparesOnlyConsecutiveTicksInPositionMode) {
  const LocalModel law = model();
  RenderingError e(1, 0);
  e.on_frame(frame(0, {1, 2, 3}, law), 0);
  e.on_frame(frame(2, {1, 2, 3}, law), 0);  // tick 1 not received: a gap
  auto forced = frame(3, {1, 2, 3}, law);
  forced.position_mode = false;
  e.on_frame(forced, 0);                    // force mode: not compared, and breaks the chain
  e.on_frame(frame(4, {1, 2, 3}, law), 0);
  e.on_frame(frame(5, {1, 2, 3}, law), 0);
  EXPECT_EQ(e.gaps(), 1u);
  EXPECT_EQ(e.compared(), 1u);
}

}  // namespace
