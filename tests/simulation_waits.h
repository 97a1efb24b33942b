#pragma once
// Waiting on a session's thread (server/sim_loop.h) from a test, bounded: its wake-ups, its
// start, a headless job. Shared by the tests that drive a Simulation without the network.
#include <poll.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>

#include <gtest/gtest.h>

#include "server/sim_loop.h"

namespace palpate::server::testing {

// Waits (bounded) for a write to the wake-up eventfd, and consumes it.
inline bool wait_for_wake(const Simulation& sim, int timeout_ms = 20000) {
  pollfd p{sim.wake_fd(), POLLIN, 0};
  if (poll(&p, 1, timeout_ms) != 1) return false;
  uint64_t value = 0;
  return read(sim.wake_fd(), &value, sizeof value) == sizeof value;
}

// Until the start has ended (ready or failed), at most `limit`.
inline void wait_until_started(const Simulation& sim, std::chrono::seconds limit = std::chrono::seconds(60)) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (sim.phase() == Phase::starting && std::chrono::steady_clock::now() < deadline) wait_for_wake(sim, 100);
  ASSERT_NE(sim.phase(), Phase::starting);
}

// One headless job of n ticks (at most `limit`); the frame it published.
inline const Snapshot& step(Simulation& sim, uint32_t n, std::chrono::seconds limit = std::chrono::seconds(60)) {
  sim.request_steps(n);
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (!sim.take_job_done() && std::chrono::steady_clock::now() < deadline) wait_for_wake(sim, 100);
  EXPECT_TRUE(sim.frames().take()) << "a job publishes its last frame";
  return sim.frames().front();
}

}  // namespace palpate::server::testing
