// The worker pool (core/thread_pool.h) and the force loops split over it (issue #17,
// "two cores for one session"): every thread runs its task once per dispatch; the split
// forces equal one thread's to round-off for every law; two runs with the same thread
// count are bit-identical over a pressed run.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <random>
#include <set>
#include <thread>

#include "core/health.h"
#include "core/mls_forces.h"
#include "core/solid.h"
#include "core/state.h"
#include "core/step.h"
#include "core/thread_pool.h"
#include "test_util.h"

namespace palpate {
namespace {

TEST(ThreadPool, OneThreadRunsOnTheCaller) {
  ThreadPool pool(1);
  EXPECT_EQ(pool.size(), 1);
  int calls = 0;
  std::thread::id where;
  pool.run([&](int t) {
    EXPECT_EQ(t, 0);
    ++calls;
    where = std::this_thread::get_id();
  });
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(where, std::this_thread::get_id());
}

TEST(ThreadPool, EveryThreadOncePerDispatchOnItsOwnThread) {
  for (int threads : {2, 3}) {
    ThreadPool pool(threads);
    ASSERT_EQ(pool.size(), threads);
    std::vector<int> count(static_cast<size_t>(threads), 0);  // each t writes only its own slot
    std::vector<std::thread::id> ids(static_cast<size_t>(threads));
    const int dispatches = 500;
    for (int k = 0; k < dispatches; ++k) {
      pool.run([&](int t) {
        ++count[static_cast<size_t>(t)];
        ids[static_cast<size_t>(t)] = std::this_thread::get_id();
      });
      // The writes of every task are visible once run returns.
      for (int t = 0; t < threads; ++t) ASSERT_EQ(count[static_cast<size_t>(t)], k + 1) << "thread " << t;
    }
    EXPECT_EQ(ids[0], std::this_thread::get_id());
    EXPECT_EQ(std::set<std::thread::id>(ids.begin(), ids.end()).size(), static_cast<size_t>(threads));
  }
}

TEST(ThreadPool, WakesSleepingWorkersAndDestroysWhileIdle) {
  {  // destroyed at once (workers maybe not even started)
    ThreadPool pool(4);
  }
  ThreadPool pool(3, /*spin_microseconds=*/1);
  std::atomic<int> total{0};
  for (int k = 0; k < 20; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));  // the workers fall asleep
    pool.run([&](int t) { total += t + 1; });
    ASSERT_EQ(total.load(), (k + 1) * 6);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(5));  // idle and asleep when destroyed
}

TEST(ThreadPool, CallerWaitsForASlowWorker) {
  ThreadPool pool(2, /*spin_microseconds=*/1);  // the caller stops spinning and sleeps
  std::atomic<int> done{0};
  pool.run([&](int t) {
    if (t == 1) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    done.fetch_add(1);
  });
  EXPECT_EQ(done.load(), 2);
}

TEST(WorkerThreads, CountsAndCopies) {
  WorkerThreads one;
  EXPECT_EQ(one.count(), 1);
  WorkerThreads two(2, 10);
  EXPECT_EQ(two.count(), 2);
  EXPECT_EQ(two.particles, 10);
  EXPECT_GE(two.rows.size(), 4u * 10u * static_cast<size_t>(row_buffers_needed(2)));
  EXPECT_EQ(reinterpret_cast<uintptr_t>(two.row_buffers(3, 10)) % 32, 0u);
  const WorkerThreads copy(two);  // a copy has no threads of its own yet
  EXPECT_EQ(copy.count(), 1);
  two.resize(1, 10);
  EXPECT_EQ(two.count(), 1);
  EXPECT_EQ(two.particles, 10);
  EXPECT_THROW(two.resize(0, 10), std::invalid_argument);
  EXPECT_THROW(two.resize(kMaxThreads + 1, 10), std::invalid_argument);
}

// A free, jittered cube of 7^3 particles (86 blocks) with the given law, displaced at random.
struct Deformed {
  Model model;
  Points x;
};
Deformed deformed_cube(const std::string& law, double volume_stiffness, const std::string& mls_extra = "") {
  Deformed d{test::model_from_json(
                 R"({"body": {"box": {"min": [0,0,0], "max": [1,1,1]}, "distribution": {"type": "jittered_grid", "per_edge": 7, "jitter": 0.25, "seed": 3}},
                     "fixed": [], "mls": {"neighbors": 20, "support_factor": 1.5)" +
                 mls_extra + R"(}, "material": {"young_modulus": 1000, "poisson_ratio": 0.3, "law": ")" + law +
                 R"(", "volume_stiffness": )" + std::to_string(volume_stiffness) + "}}"),
             {}};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.03, 0.03);
  d.x = d.model.rest_position;
  for (int i = 0; i < d.x.cols(); ++i) d.x.col(i) += Vec3(u(rng), u(rng), u(rng)) + 0.1 * d.x(0, i) * Vec3(0, 0, 1);
  return d;
}

double max_relative_difference(const Points& a, const Points& b) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(a.cwiseAbs().maxCoeff(), 1e-300);
}

bool bit_identical(const Points& a, const Points& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<size_t>(a.size())) == 0;
}

TEST(ParallelForces, EqualOneThreadToRoundOffForEveryLaw) {
  for (const char* law : {"stvk", "corotational", "neo_hookean", "linear"}) {
    for (double k_v : {0.0, 500.0}) {
      // Hourglass control with the volume term, without it the plain loop.
      const std::string hourglass = k_v > 0 ? R"(, "hourglass": 0.1)" : "";
      SCOPED_TRACE(std::string(law) + ", volume_stiffness " + std::to_string(k_v) + hourglass);
      const Deformed d = deformed_cube(law, k_v, hourglass);
      ASSERT_TRUE(detail::uses_blocked_loops(d.model));
      const int n = d.model.particle_count;
      Points f1(3, n);
      mls_internal_forces(d.model, d.x, f1);
      // Tangent at x, applied to a random direction, on one thread.
      std::vector<double> F1, S1;
      mls_linearize(d.model, d.x, F1, S1);
      const Points dx = Points::Random(3, n);
      Points df1(3, n);
      mls_force_differential(d.model, F1, S1, dx, df1);
      // threads = 1 through the pool's entry point: the single-thread function, bit for bit;
      // 2, 3 and more threads than blocks: equal to round-off.
      for (int threads : {1, 2, 3, 40}) {
        SCOPED_TRACE("threads " + std::to_string(threads));
        WorkerThreads w(threads, n);
        Points f(3, n), f_again(3, n);
        f.setConstant(1.0);  // overwritten
        mls_internal_forces(d.model, d.x, f, w);
        mls_internal_forces(d.model, d.x, f_again, w);
        EXPECT_TRUE(bit_identical(f, f_again));
        const double diff = max_relative_difference(f1, f);
        EXPECT_LE(diff, 1e-12);
        if (threads == 1) {
          EXPECT_TRUE(bit_identical(f, f1));
        }
        std::vector<double> F, S;
        mls_linearize(d.model, d.x, F, S, w);
        EXPECT_TRUE(F == F1 && S == S1);  // per particle, no sums: identical
        Points df(3, n);
        mls_force_differential(d.model, F, S, dx, df, w);
        EXPECT_LE(max_relative_difference(df1, df), 1e-12);
        if (threads == 1) {
          EXPECT_TRUE(bit_identical(df, df1));
        }
      }
    }
  }
}

TEST(ParallelForces, PerParticleLoopsStayOnOneThread) {
  Deformed d = deformed_cube("stvk", 0.0, R"(, "hourglass": 0.1)");
  d.model.blocks.clear();  // a model without the blocked layout
  ASSERT_FALSE(detail::uses_blocked_loops(d.model));
  Points f1(3, d.model.particle_count), f2(3, d.model.particle_count);
  mls_internal_forces(d.model, d.x, f1);
  WorkerThreads w(2, d.model.particle_count);
  mls_internal_forces(d.model, d.x, f2, w);
  EXPECT_TRUE(bit_identical(f1, f2));
}

// A scene pressed with `force` for `steps` steps on `threads` threads.
struct PressedRun {
  Points position;
  Vec3 indenter{0, 0, 0}, contact{0, 0, 0};
  double kinetic = 0, position_sum = 0;  // the last update pass's sums (health.h)
};
PressedRun pressed_run(const test::Setup& s, int threads, int steps, double force) {
  Options opt = s.opt;
  opt.integrator.threads = threads;
  State state = make_state(s.model, opt);
  EXPECT_EQ(state.work.threads.count(), threads);
  state.indenter_center.z() = s.model.touch_height;
  reset_health(s.model, opt, state);  // the energy check counts the tool's travel from here
  state.force_command = press_down(force);
  for (int k = 0; k < steps; ++k) {
    const StepStatus status = step(s.model, opt, state);
    EXPECT_FALSE(is_fault(status)) << to_string(status) << " at step " << k;
  }
  EXPECT_GT(state.contact_index.size(), 0u);
  return {state.position, state.indenter_center, state.indenter_contact_force, state.out.free_motion_kinetic,
          state.out.free_motion_position_sum};
}

// Two runs on two threads are bit-identical; one and two threads differ by the order of
// the force sums (and of the update passes' sums over the coordinates) only: round-off.
void expect_pressed_runs_agree(const test::Setup& s, int steps, double force) {
  const PressedRun one = pressed_run(s, 1, steps, force);
  const PressedRun a = pressed_run(s, 2, steps, force), b = pressed_run(s, 2, steps, force);
  EXPECT_TRUE(bit_identical(a.position, b.position));
  EXPECT_EQ(std::memcmp(a.indenter.data(), b.indenter.data(), sizeof(double) * 3), 0);
  EXPECT_EQ(std::memcmp(a.contact.data(), b.contact.data(), sizeof(double) * 3), 0);
  EXPECT_EQ(a.kinetic, b.kinetic);
  EXPECT_EQ(a.position_sum, b.position_sum);
  // Round-off, grown over the run (printed for the record).
  const double displacement = (one.position - s.model.rest_position).cwiseAbs().maxCoeff();
  const double position_diff = (one.position - a.position).cwiseAbs().maxCoeff() / displacement;
  const double contact_diff = (one.contact - a.contact).norm() / one.contact.norm();
  std::printf("%s: threads 1 vs 2 after %d steps: max |dx| / max displacement %.3g, |d contact force| / |F| %.3g\n",
              s.scene.name.c_str(), steps, position_diff, contact_diff);
  EXPECT_LT(position_diff, 1e-9);
  EXPECT_LT(contact_diff, 1e-9);
  EXPECT_NEAR(a.kinetic, one.kinetic, 1e-6 * one.kinetic);
  EXPECT_NEAR(a.position_sum, one.position_sum, 1e-9 * std::abs(one.position_sum));
  EXPECT_GT(one.kinetic, 0.0);
}

TEST(ParallelForces, PressedRunIsBitIdenticalForAGivenThreadCount) {
  // The accurate haptic scene (symplectic Euler).
  expect_pressed_runs_agree(
      test::setup_from(load_scene(std::filesystem::path(PALPATE_SOURCE_DIR) / "scenes" / "hertz_cube_haptic.json")),
      200, 120.0);
}

TEST(ParallelForces, Rk4PressedRunIsBitIdenticalForAGivenThreadCount) {
  // The paper's cube (RK4: four update passes per step, split over the threads too).
  expect_pressed_runs_agree(
      test::setup_from(load_scene(std::filesystem::path(PALPATE_SOURCE_DIR) / "scenes" / "hertz_cube.json")), 100,
      120.0);
}

TEST(ParallelForces, ThreadCountMayChangeBetweenSteps) {
  const test::Setup s =
      test::setup_from(load_scene(std::filesystem::path(PALPATE_SOURCE_DIR) / "scenes" / "hertz_cube_haptic.json"));
  Options opt = s.opt;
  State state = make_state(s.model, opt);
  state.force_command = press_down(50.0);
  for (int threads : {2, 1, 3, 1}) {
    opt.integrator.threads = threads;
    for (int k = 0; k < 5; ++k) EXPECT_FALSE(is_fault(step(s.model, opt, state)));
    EXPECT_EQ(state.work.threads.count(), threads);
  }
  const State copy = state;  // a copy makes its own pool when it steps
  EXPECT_EQ(copy.work.threads.count(), 1);
}

TEST(ParallelForces, SceneField) {
  const std::string base = R"({"body": {"distribution": {"type": "grid", "per_edge": 4}}, "integrator": )";
  EXPECT_EQ(test::scene_from_json(base + R"({"threads": 2}})").integrator.threads, 2);
  EXPECT_EQ(test::scene_from_json(base + "{}}").integrator.threads, 1);
  EXPECT_THROW(test::scene_from_json(base + R"({"threads": 0}})"), SceneError);
  EXPECT_THROW(test::scene_from_json(base + R"({"threads": 65}})"), SceneError);
  EXPECT_THROW(test::scene_from_json(base + R"({"thread": 2}})"), SceneError);  // unknown field
}

}  // namespace
}  // namespace palpate
