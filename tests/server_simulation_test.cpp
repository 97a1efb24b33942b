// A session's thread (server/sim_loop.h) without the network: the start (scene
// preparation on the thread, failures, cancelling), the recovery from blow-ups, and
// the bounded command queue. Headless sessions stepped one tick per job publish
// every tick's frame, so the tests see every frame a subscriber could get.
#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <functional>
#include <limits>
#include <mutex>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/scene.h"
#include "server/sim_loop.h"
#include "tests/simulation_waits.h"

namespace palpate::server {
namespace {

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// 5^3 particles, the paper's material and RK4 at 1 ms (stable), an initial force of 5 N.
Scene small_scene(const SceneOverrides& overrides = {}) {
  return parse_scene(R"({"body": {"distribution": {"per_edge": 5}}, "indenter": {"force": 5},
                        "verify": {"forces": [10, 20]}})",
                     "<test scene>", ".", overrides);
}

SimConfig headless() {
  SimConfig c;
  c.headless = true;
  c.try_realtime = false;
  c.checkpoint_interval = 100;
  return c;
}

using testing::step;
using testing::wait_for_wake;
using testing::wait_until_started;

bool finite(const Snapshot& s) {
  bool ok = std::isfinite(s.sim_time) && s.tool_velocity.allFinite() && s.tool_contact_force.allFinite() &&
            std::isfinite(s.indentation) && s.force_command.allFinite() && s.tool_position.allFinite() &&
            s.render_force.allFinite() && s.contact_model.stiffness.allFinite() &&
            s.render_model.stiffness.allFinite();
  for (float x : s.positions) ok = ok && std::isfinite(x);
  for (float x : s.contact_forces) ok = ok && std::isfinite(x);
  return ok;
}

TEST(Simulation, TheSceneIsPreparedOnTheSessionsThread) {
  std::thread::id prepared_on;
  Simulation sim(headless(), [&prepared_on]() {
    prepared_on = std::this_thread::get_id();
    return small_scene();
  });
  wait_until_started(sim);
  ASSERT_EQ(sim.phase(), Phase::ready);
  EXPECT_NE(prepared_on, std::this_thread::get_id());
  EXPECT_EQ(sim.shown_model().particle_count, 125);
  EXPECT_EQ(sim.scene().source, "<test scene>");
  // The rest state is published before the session is ready.
  ASSERT_TRUE(sim.frames().take());
  EXPECT_EQ(sim.frames().front().tick, 0);
  EXPECT_EQ(sim.frames().front().force_command, press_down(5.0));
}

TEST(Simulation, AFailedPreparationFailsTheSessionWithItsMessage) {
  Simulation sim(headless(), []() -> Scene {
    throw std::runtime_error("<rpc scene>: /material/poisson_ratio: must be a number in (-1, 0.5), got 0.7");
  });
  wait_until_started(sim);
  EXPECT_EQ(sim.phase(), Phase::failed);
  EXPECT_EQ(sim.status().error, "<rpc scene>: /material/poisson_ratio: must be a number in (-1, 0.5), got 0.7");
}

TEST(Simulation, AFailedBuildFailsTheSessionWithItsMessage) {
  Simulation sim(headless(), small_scene({{"integrator.dt", "0.5"}}));  // far outside the stable envelope
  wait_until_started(sim);
  EXPECT_EQ(sim.phase(), Phase::failed);
  EXPECT_TRUE(contains(sim.status().error, "/integrator/dt")) << sim.status().error;
}

// cancel() never waits: a start in progress ends after its stage, as failed, and
// builds nothing more. Its preparation blocks until released after cancel() returns, so
// a cancel() that waited for the start would never return (the test would hang to its
// ctest timeout). Returns how long cancel() took.
std::chrono::steady_clock::duration cancel_a_start_in_preparation() {
  std::mutex m;
  std::condition_variable cv;
  bool release = false, preparing = false;
  auto sim = std::make_unique<Simulation>(headless(), [&]() {
    std::unique_lock<std::mutex> lock(m);
    preparing = true;
    cv.notify_all();
    cv.wait(lock, [&] { return release; });  // a slow validation or file read
    return small_scene();
  });
  {
    std::unique_lock<std::mutex> lock(m);
    cv.wait(lock, [&] { return preparing; });
  }
  const auto t0 = std::chrono::steady_clock::now();
  sim->cancel();
  const auto took = std::chrono::steady_clock::now() - t0;
  EXPECT_EQ(sim->phase(), Phase::starting);
  {
    std::lock_guard<std::mutex> lock(m);
    release = true;
  }
  cv.notify_all();
  wait_until_started(*sim);
  EXPECT_EQ(sim->phase(), Phase::failed);
  EXPECT_EQ(sim->status().error, "session closed while starting");
  sim->stop();  // a short join: the thread has ended
  sim.reset();
  return took;
}

TEST(Simulation, CancellingAStartNeverWaitsForIt) { cancel_a_start_in_preparation(); }

// Timing (ctest label `timing`): cancel() returns within 50 ms of wall time.
TEST(SimulationTiming, CancellingAStartReturnsAtOnce) {
  EXPECT_LT(cancel_a_start_in_preparation(), std::chrono::milliseconds(50));
}

// The recovery path, driven by NaNs injected through the test hook: a first blow-up
// restores the last checkpoint, a second one within 2 checkpoint intervals restores
// the rest state and the scene's initial force, a later one the checkpoint again.
TEST(Simulation, BlowUpsRecoverFromTheCheckpointThenFromRest) {
  // The hook sees the state before a step, i.e. at the previous tick: a NaN injected
  // at tick t is caught by the step to tick t + 1.
  const std::set<int64_t> inject = {249, 299, 599};
  SimConfig config = headless();
  config.before_step_for_tests = [&inject](State& s) {
    if (inject.count(s.tick)) s.velocity.setConstant(std::numeric_limits<double>::quiet_NaN());
  };
  Simulation sim(config, small_scene());
  wait_until_started(sim);
  ASSERT_EQ(sim.phase(), Phase::ready);
  ASSERT_TRUE(sim.frames().take());
  const std::vector<float> rest = sim.frames().front().positions;
  ASSERT_EQ(rest.size(), 3u * 125);

  ASSERT_GT(sim.enqueue(CommandType::set_force, press_down(40.0)), 0u);
  std::vector<std::vector<float>> positions(701);  // by tick
  std::vector<uint32_t> recoveries(701);
  for (int64_t tick = 1; tick <= 700; ++tick) {
    const Snapshot& f = step(sim, 1);
    ASSERT_EQ(f.tick, tick);
    ASSERT_TRUE(finite(f)) << "a non-finite frame at tick " << tick;
    positions[tick] = f.positions;
    recoveries[tick] = f.recoveries;
    if (tick == 250) {  // 1st: the checkpoint of tick 200, the command kept
      EXPECT_EQ(f.recoveries, 1u);
      EXPECT_EQ(f.positions, positions[200]);
      EXPECT_EQ(f.force_command, press_down(40.0));
      const SimStatus st = sim.status();
      EXPECT_EQ(st.blow_ups, 1u);
      EXPECT_EQ(st.last_blow_up_tick, 250);
      EXPECT_TRUE(contains(st.last_blow_up, "non-finite")) << st.last_blow_up;
      EXPECT_TRUE(contains(st.last_blow_up, "restored the last checkpoint (every 100 ticks)")) << st.last_blow_up;
    }
    if (tick == 300) {  // 2nd, 50 ticks later: the rest state and the scene's initial force
      EXPECT_EQ(f.recoveries, 2u);
      EXPECT_EQ(f.positions, rest);
      EXPECT_EQ(f.force_command, press_down(5.0));
      const SimStatus st = sim.status();
      EXPECT_EQ(st.blow_ups, 2u);
      EXPECT_EQ(st.last_blow_up_tick, 300);
      EXPECT_EQ(st.force_command, 5.0);
      EXPECT_TRUE(contains(st.last_blow_up, "restored the rest state and the scene's initial force (5.000000 N; "
                                            "the command was 40.000000 N)"))
          << st.last_blow_up;
    }
    if (tick == 600) {  // 3rd, 300 ticks after the 2nd: the checkpoint again (tick 500)
      EXPECT_EQ(f.recoveries, 3u);
      EXPECT_EQ(f.positions, positions[500]);
      EXPECT_TRUE(contains(sim.status().last_blow_up, "restored the last checkpoint")) << sim.status().last_blow_up;
    }
  }
  EXPECT_EQ(recoveries[249], 0u);
  EXPECT_EQ(recoveries[299], 1u);
  EXPECT_EQ(recoveries[599], 2u);
  EXPECT_EQ(recoveries[700], 3u);
  const SimCounters c = sim.counters();
  EXPECT_EQ(c.blow_ups, 3u);
  EXPECT_EQ(c.ticks, 700);
  EXPECT_EQ(c.frames_published, 701u);  // the rest frame and one per job
  EXPECT_EQ(c.frames_coalesced, 0u);
  EXPECT_EQ(sim.status().last_blow_up_tick, 600);
}

// A genuinely unstable scene (RK4 1.2x beyond its stability limit, opted in): caught
// while still a body, recovered, and never published.
TEST(Simulation, AnUnstableSceneIsRecoveredAndNeverPublished) {
  Simulation sim(headless(), small_scene({{"body.distribution.per_edge", "8"},
                                         {"material.young_modulus", "2e8"},
                                         {"integrator.allow_unstable_dt", "true"}}));
  wait_until_started(sim);
  ASSERT_EQ(sim.phase(), Phase::ready);
  ASSERT_GT(sim.enqueue(CommandType::set_force, press_down(100.0)), 0u);
  for (int tick = 1; tick <= 1000; ++tick) {
    const Snapshot& f = step(sim, 1);
    ASSERT_TRUE(finite(f)) << "a non-finite frame at tick " << f.tick;
    for (float x : f.positions) ASSERT_LT(std::abs(x), 4.0f) << "tick " << f.tick;  // the cube spans |x| <= 2 m
  }
  const SimStatus st = sim.status();
  EXPECT_GE(st.blow_ups, 1u);
  EXPECT_TRUE(contains(st.last_blow_up, "restored")) << st.last_blow_up;
  EXPECT_GE(st.last_blow_up_tick, 1);
}

// A full queue refuses the command: no sequence number is used, nothing changes.
TEST(Simulation, AFullCommandQueueRefusesCommands) {
  Simulation sim(headless(), small_scene());
  wait_until_started(sim);
  ASSERT_EQ(sim.phase(), Phase::ready);
  for (uint64_t k = 1; k <= kMaxQueuedCommands; ++k)
    ASSERT_EQ(sim.enqueue(CommandType::set_force, press_down(static_cast<double>(k % 50))), k);
  EXPECT_EQ(sim.enqueue(CommandType::set_force, press_down(49.5)), 0u);
  EXPECT_EQ(sim.enqueue(CommandType::reset), 0u);
  const Snapshot& f = step(sim, 1);  // drains the queue
  EXPECT_EQ(f.command_seq, kMaxQueuedCommands);
  EXPECT_EQ(f.force_command, press_down(static_cast<double>(kMaxQueuedCommands % 50)));
  EXPECT_EQ(f.tick, 1) << "the refused reset was not applied";
  EXPECT_EQ(sim.enqueue(CommandType::set_force, press_down(1.0)), kMaxQueuedCommands + 1);
}


// A subscriber of a derived field (Frame.vonMises, displacementMagnitude) makes the loop copy
// the double-precision positions into the frame (Snapshot::body_position): into the three
// slots preallocated at the start (never another buffer: the loop does not allocate), only
// while one is wanted, and equal to the single-precision positions it also publishes.
TEST(Simulation, DerivedFieldsCopyThePositionsIntoPreallocatedSlots) {
  SimConfig config;
  config.headless = false;
  config.try_realtime = false;
  config.rate_hz = 1000;
  Simulation sim(config, small_scene());
  wait_until_started(sim);
  ASSERT_EQ(sim.phase(), Phase::ready);
  const int n = sim.shown_model().particle_count;
  // Calls check on every frame taken for ms milliseconds, while it is the reader's: the loop
  // writes a slot again once the reader has taken another (a pointer kept past the next take()
  // would be read while the loop refills it).
  auto each_frame_for = [&](int ms, const std::function<void(const Snapshot&)>& check) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    while (std::chrono::steady_clock::now() < deadline) {
      wait_for_wake(sim, 50);
      if (sim.frames().take()) check(sim.frames().front());
    }
  };
  const auto skip = [](const Snapshot&) {};
  sim.set_wanted(false, false, false);
  each_frame_for(50, skip);  // frames published before the change are gone
  each_frame_for(100, [](const Snapshot& s) { EXPECT_FALSE(s.has_body_position) << "tick " << s.tick; });
  sim.set_wanted(true, false, true);
  each_frame_for(20, skip);
  std::set<const double*> buffers;
  size_t checked = 0;
  each_frame_for(200, [&](const Snapshot& s) {
    ASSERT_TRUE(s.has_body_position) << "tick " << s.tick;
    ASSERT_EQ(s.body_position.cols(), n);
    buffers.insert(s.body_position.data());
    ASSERT_EQ(s.positions.size(), 3 * static_cast<size_t>(n));
    for (size_t k = 0; k < s.positions.size(); ++k)
      ASSERT_EQ(s.positions[k], static_cast<float>(s.body_position.data()[k])) << "tick " << s.tick << ", entry " << k;
    ++checked;
  });
  EXPECT_GE(checked, 20u);
  EXPECT_LE(buffers.size(), 3u) << "the triple buffer's slots, no others";
  sim.stop();
}

}  // namespace
}  // namespace palpate::server
