#pragma once
// One simulation session's thread: builds the Model, then either runs the
// fixed-rate real-time loop on absolute deadlines or (headless) steps on request.
//
// Threading: the thread holds no KJ objects. The RPC thread talks to it through
//  - commands: enqueue() (a short mutex), drained at the start of each tick;
//  - headless jobs: request_steps() (mutex + condition variable);
//  - results: the TripleBuffer (newest frame), atomics (status, counters) and
//    lock-free histograms; every publish writes 1 to wake_fd() (an eventfd),
//    which the RPC thread watches.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/checkpoint.h"
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"
#include "server/snapshot.h"

namespace palpate::server {

int64_t now_ns();  // CLOCK_MONOTONIC

// Lock-free histogram of durations in microseconds: 1 us bins to 5 ms, then
// 1 ms bins to 1 s, and an exact maximum. One writer thread, any readers.
class Histogram {
 public:
  void add(double us);
  void clear();  // writer thread only
  struct Summary {
    double p50 = 0, p99 = 0, max = 0;
    uint64_t count = 0;
  };
  Summary summary() const;

 private:
  static constexpr int kFine = 5000, kCoarse = 995;  // 0..5 ms by 1 us, 5 ms..1 s by 1 ms
  std::atomic<uint64_t> bins_[kFine + kCoarse + 1] = {};
  std::atomic<uint64_t> count_{0};
  std::atomic<double> max_{0.0};
};

struct SimConfig {
  Scene scene;
  bool headless = false;
  double rate_hz = 1000.0;
  double spin_margin_us = 200.0;  // sleep until this long before the deadline, then spin
  bool try_realtime = true;       // ask for SCHED_FIFO (silently refused when not allowed)
  int checkpoint_interval = 100;  // ticks between checkpoints of the last good state
};

enum class CommandType { set_force, reset, pause, resume };

enum class Phase { starting, ready, failed };

struct SimCounters {
  int64_t ticks = 0;  // stepped since start
  double elapsed_s = 0.0;
  double stepping_s = 0.0;  // wall time spent inside step() (headless rate)
  uint64_t deadline_misses = 0, skipped_ticks = 0, frames_published = 0, frames_coalesced = 0;
  uint32_t blow_ups = 0;
  bool realtime_priority = false;
  Histogram::Summary step_us, lateness_us;
};

struct SimStatus {
  Phase phase = Phase::starting;
  bool paused = false;
  int64_t tick = 0;
  double sim_time = 0.0;
  double force_command = 0.0;
  uint32_t blow_ups = 0;
  std::string last_blow_up;
  int64_t last_blow_up_tick = -1;
  std::string error;  // phase == failed
};

class Simulation {
 public:
  explicit Simulation(SimConfig config);
  ~Simulation();  // stop()
  Simulation(const Simulation&) = delete;
  Simulation& operator=(const Simulation&) = delete;

  // Stops and joins the thread (idempotent). After it no more wake-ups happen.
  void stop();

  int wake_fd() const { return wake_fd_; }
  Phase phase() const { return phase_.load(std::memory_order_acquire); }
  const Model& model() const { return *model_; }  // phase() == ready
  const SimConfig& config() const { return config_; }
  double build_seconds() const { return build_seconds_; }

  // RPC thread. Returns the command's sequence number (> 0).
  uint64_t enqueue(CommandType type, double value = 0.0);
  // The subscribers' needs, read by the loop at each publish.
  void set_wanted(bool positions, bool contacts) {
    want_positions_.store(positions, std::memory_order_relaxed);
    want_contacts_.store(contacts, std::memory_order_relaxed);
  }

  // Headless: start a job of n ticks; job_done() turns true (and wake_fd fires)
  // when it finished and its last frame is published. One job at a time.
  void request_steps(uint32_t n);
  bool take_job_done() { return job_done_.exchange(false, std::memory_order_acq_rel); }

  TripleBuffer& frames() { return frames_; }
  int64_t newest_tick() const { return status_tick_.load(std::memory_order_relaxed); }

  SimCounters counters() const;
  SimStatus status() const;

 private:
  struct Command {
    CommandType type;
    double value;
    uint64_t seq;
  };

  void run();
  void run_realtime();
  void run_headless();
  // Drains commands and steps once; false when paused (no step).
  bool tick_once();
  void recover(const std::string& what);
  void publish();
  void notify();

  SimConfig config_;
  int wake_fd_ = -1;
  std::unique_ptr<Model> model_;
  Options options_;  // the scene's (options_of); the loop steps with them
  std::unique_ptr<State> state_;
  double divergence_bound_ = 0.0;  // m, see diverged() in sim_loop.cpp
  std::unique_ptr<Checkpoint> rest_, checkpoint_;
  double build_seconds_ = 0.0;

  std::atomic<Phase> phase_{Phase::starting};
  std::atomic<bool> stop_{false};
  std::atomic<bool> want_positions_{false}, want_contacts_{false};

  std::mutex command_mutex_;
  std::vector<Command> commands_, drained_;
  uint64_t next_seq_ = 1;  // RPC thread (under command_mutex_)

  std::mutex job_mutex_;
  std::condition_variable job_cv_;
  uint32_t job_ticks_ = 0;
  bool job_pending_ = false;
  std::atomic<bool> job_done_{false};

  TripleBuffer frames_;

  // Loop-thread state.
  bool paused_ = false;
  uint64_t applied_seq_ = 0;
  int64_t ticks_since_recovery_ = -1;  // -1: never recovered

  // Published counters.
  std::atomic<int64_t> ticks_{0};
  std::atomic<int64_t> start_ns_{0}, last_tick_ns_{0};
  std::atomic<int64_t> stepping_ns_{0};
  std::atomic<uint64_t> deadline_misses_{0}, skipped_ticks_{0}, frames_published_{0}, frames_coalesced_{0};
  std::atomic<uint32_t> blow_ups_{0};
  std::atomic<bool> realtime_priority_{false};
  std::atomic<bool> paused_flag_{false};
  std::atomic<int64_t> status_tick_{0};
  std::atomic<double> status_time_{0.0}, status_force_{0.0};
  Histogram step_us_, lateness_us_;
  mutable std::mutex text_mutex_;  // guards the strings below
  std::string last_blow_up_, error_;
  int64_t last_blow_up_tick_ = -1;

  std::thread thread_;
};

}  // namespace palpate::server
