#pragma once
// One simulation session's thread: resolves and validates the scene (file reads
// included), builds the Model, then either runs the fixed-rate real-time loop on
// absolute deadlines or (headless) steps on request.
//
// Threading: the thread holds no KJ objects. The RPC thread talks to it through
//  - commands: enqueue() (a short mutex), drained at the start of each tick;
//  - headless jobs: request_steps() (mutex + condition variable);
//  - results: the triple buffer (newest frame; the sim thread holds its writer,
//    the RPC thread its reader), atomics (phase, status, counters) and lock-free
//    histograms; every publish, and the end of the start (ready or failed), writes
//    1 to wake_fd() (an eventfd), which the RPC thread watches.
// Every member below says which thread may touch it.
//
// A scene whose cloud follows the tool (core/refocus.h, follows_tool) is stepped on the cloud
// a FollowingModel keeps refined under the tool: built and shadowed on its worker thread in
// real time, inline (at SimConfig::refocus.latency, deterministic) when headless. Clients are
// shown the base mesh (shown_model()): the first particles of every cloud, one topology; the
// contact forces on the cloud are shared out to the base's vertices (base_weights, the total
// kept), and the force a frame gives carries the swap's fading offset (docs/physics.md (7.3)).
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/checkpoint.h"
#include "core/model.h"
#include "core/reference_file.h"
#include "core/options.h"
#include "core/refocus.h"
#include "core/scene.h"
#include "core/state.h"
#include "server/deadlines.h"
#include "server/haptic_loop.h"
#include "server/histogram.h"
#include "server/local_model.h"
#include "server/snapshot.h"

namespace palpate::server {

// Unapplied commands a session holds; enqueue() refuses beyond.
constexpr size_t kMaxQueuedCommands = 4096;

// What the haptic device can render (OpenRequest.device); 0 = no limit.
struct DeviceLimits {
  double max_stiffness = 0.0;  // N/m
  double max_damping = 0.0;    // N s/m
  double max_force = 0.0;      // N
};

// The coupling of position commands (Options::coupling) within the device's limits.
CouplingOptions clamp_to_device(CouplingOptions c, const DeviceLimits& device);

// The coupling a position command gets unless the client asks for another: as stiff
// as the contact of the sphere at d = R / 5 by Hertz (dF/dd = 2 E* sqrt(R d),
// docs/physics.md §3), critically damped for the tool's mass (b = 2 sqrt(k M)), within
// the device's limits.
CouplingOptions default_coupling(const Model& model, const Options& opt, const DeviceLimits& device);

// How a session runs; known before its scene is.
struct SimConfig {
  bool headless = false;
  double rate_hz = 1000.0;
  // Multirate (server/haptic_loop.h): > 0 starts a HapticRenderer at this rate beside the
  // loop (real time only); 0: none, a frame per step.
  double haptic_rate_hz = 0.0;
  double spin_margin_us = 200.0;  // sleep until this long before the deadline, then spin
  bool try_realtime = true;       // ask for SCHED_FIFO (silently refused when not allowed)
  // The core the real-time loop pins itself to (-1: none). The server gives each real-time
  // session one of cores 1 ... n-1 in turn and keeps the RPC thread, the stiffness workers
  // and headless sessions on the others (palpate-server --pin turns it on).
  int cpu = -1;
  int checkpoint_interval = 100;  // ticks between checkpoints of the last good state
  DeviceLimits device;            // OpenRequest.device
  CouplingOptions coupling;       // OpenRequest.coupling; stiffness 0 = default_coupling()
  // Compute the contact stiffness of the frames' local models (StiffnessSource): on a
  // worker thread in real time, at each publish when headless. Off: stiffness zero.
  bool contact_stiffness = true;
  // The stiffness at first touch's lookahead (s, docs/physics.md (2.22),
  // ContactStiffness::set_touch_lookahead): headless, this fixed time (0: at the touch);
  // in real time the worker sets it from its own evaluations' durations.
  double touch_lookahead = 0.0;
  // Where the stored finite-block references are (palpate-reference --out): the one whose
  // key matches the session's scene is read on the session's thread at its start and
  // given to clients (SessionInfo.reference*). Empty: none looked up.
  std::filesystem::path reference_dir;
  // How a scene whose cloud follows the tool refocuses (core/refocus.h); latency is the
  // headless sessions' fixed delay from an ask to the carry.
  RefocusOptions refocus;
  // The server's RPC thread's heartbeat (server/deadlines.h): a real-time loop granted
  // SCHED_FIFO gives way when it is stale (Deadlines::give_way_to). Null: never.
  const RpcHeartbeat* rpc_heartbeat = nullptr;
  // TEST HOOK (tests/server_simulation_test.cpp only; empty in the server): called on
  // the session's thread with the state just before each step, e.g. to inject a NaN.
  std::function<void(State&)> before_step_for_tests;
};

// Gives the session's scene, on the session's thread (validation and file reads,
// which must not run on the RPC thread). What it throws fails the session, and
// its what() is the message the client gets.
using ScenePreparer = std::function<Scene()>;

// set_force: Command::value is the force on the tool (N, world frame), force mode;
// set_position: value is the device position (m), position mode;
// set_coupling: value = (k N/m, b N s/m, unused), already clamped to the device.
enum class CommandType { set_force, set_position, set_coupling, reset, pause, resume };

enum class Phase { starting, ready, failed };

struct SimCounters {
  int64_t ticks = 0;  // stepped since start
  double elapsed_s = 0.0;
  double stepping_s = 0.0;  // wall time spent inside step() (headless rate)
  uint64_t deadline_misses = 0, skipped_ticks = 0, frames_published = 0, frames_coalesced = 0;
  // The misses by cause: the tick started over half a period late (the host did not run the
  // thread in time), or it started in time and its step overran.
  uint64_t misses_late_start = 0, misses_long_step = 0;
  uint32_t blow_ups = 0;
  bool realtime_priority = false;
  bool pinned = false;  // the loop runs on SimConfig::cpu only
  uint64_t stiffness_evaluations = 0;
  uint64_t watchdog_rests = 0;  // the loop slept to let other threads run (server/deadlines.h)
  Histogram::Summary step_us, lateness_us;
  HapticCounters haptic;  // multirate only
  // A scene whose cloud follows the tool: refocuses swapped in, and dropped (core/refocus.h).
  int64_t refocuses = 0, refocuses_dropped = 0;
};

struct SimStatus {
  Phase phase = Phase::starting;
  bool paused = false;
  int64_t tick = 0;
  double sim_time = 0.0;
  double force_command = 0.0;  // N, pressing (-z of the force command)
  bool position_mode = false;
  uint32_t blow_ups = 0;
  std::string last_blow_up;
  int64_t last_blow_up_tick = -1;
  std::string error;  // phase == failed
  std::string last_refocus_drop;  // why the last refocus was dropped (core/refocus.h); empty if none
};

class Simulation {
 public:
  // Starts the thread; it runs prepare() for the scene, then builds the model.
  Simulation(SimConfig config, ScenePreparer prepare);
  // The same with a scene already validated.
  Simulation(SimConfig config, Scene scene);
  ~Simulation();  // stop()
  Simulation(const Simulation&) = delete;
  Simulation& operator=(const Simulation&) = delete;

  // Any thread, never blocks: asks the thread to end. A start in progress ends
  // after the stage it is in (preparing the scene, building the model) as failed.
  void cancel();
  // The owner's thread: cancel() and join (idempotent). After it no more wake-ups happen.
  void stop();

  int wake_fd() const { return wake_fd_; }
  Phase phase() const { return phase_.load(std::memory_order_acquire); }
  const SimConfig& config() const { return config_; }
  // After phase() == ready only (any thread; constant from then on).
  const Scene& scene() const { return scene_; }
  // The model clients are shown (SessionInfo, frames, derived fields): the stepped model, or
  // for a scene whose cloud follows the tool, the base mesh's (its particles are the first of
  // every cloud stepped).
  const Model& shown_model() const { return *shown_; }
  double build_seconds() const { return build_seconds_; }
  // The options the loop started with (the scene's), and the coupling in effect at the
  // start (default_coupling, or the request's clamped): after phase() == ready only.
  const Options& initial_options() const { return initial_options_; }
  // The stored reference of the scene (SimConfig::reference_dir), if there is one: after
  // phase() == ready only.
  const std::optional<Reference>& reference() const { return reference_; }
  CouplingOptions initial_coupling() const { return initial_coupling_; }

  // RPC thread. Returns the command's sequence number (> 0), or 0 when the queue
  // already holds kMaxQueuedCommands commands (then nothing is queued or numbered).
  uint64_t enqueue(CommandType type, const Vec3& value = Vec3::Zero());
  // The subscribers' needs, read by the loop at each publish. derived: a field computed from
  // the double-precision positions (Snapshot::body_position) on the RPC thread.
  void set_wanted(bool positions, bool contacts, bool derived = false) {
    want_positions_.store(positions, std::memory_order_relaxed);
    want_contacts_.store(contacts, std::memory_order_relaxed);
    want_derived_.store(derived, std::memory_order_relaxed);
  }

  // Headless: start a job of n ticks; take_job_done() turns true (and wake_fd fires)
  // when it finished and its last frame is published. One job at a time.
  void request_steps(uint32_t n);
  bool take_job_done() { return job_done_.exchange(false, std::memory_order_acq_rel); }

  // The reader of the published frames: one consumer thread only (the RPC thread),
  // after phase() == ready.
  SnapshotBuffer::Reader& frames() { return frames_reader_; }
  int64_t newest_tick() const { return status_tick_.load(std::memory_order_relaxed); }

  // Multirate: the force renderer (null when SimConfig::haptic_rate_hz is 0 or headless);
  // after phase() == ready. Its samples() and offer_device() are the RPC thread's
  // (enqueue(set_position) offers the device position itself).
  HapticRenderer* haptic() { return haptic_.get(); }

  SimCounters counters() const;  // any thread
  SimStatus status() const;      // any thread

 private:
  struct Command {
    CommandType type;
    Vec3 value;
    uint64_t seq;
  };

  void start();
  void run();
  void prepare_and_build();
  void run_realtime();
  void run_headless();
  void configure_workers(bool realtime);
  // Drains commands and steps once; false when paused (no step).
  bool tick_once();
  void recover(const std::string& what);
  void set_position_mode(bool on);
  void fill_local_models(Snapshot& s, const Vec3& contact_force) const;
  void take_new_cloud();
  void show_contacts(Snapshot& s);
  void publish();
  void notify();

  // Set at construction, then constant (any thread).
  const SimConfig config_;
  int wake_fd_ = -1;

  // Sim thread only until phase ready, then constant and readable by any thread.
  ScenePreparer prepare_;  // sim thread only (run once, then released)
  Scene scene_;
  std::unique_ptr<Model> model_;                // the model stepped, unless the cloud follows the tool
  std::unique_ptr<FollowingModel> following_;  // the cloud that follows the tool (else null)
  const Model* shown_ = nullptr;               // see shown_model()
  double build_seconds_ = 0.0;
  std::optional<Reference> reference_;
  Options initial_options_;
  CouplingOptions initial_coupling_;

  // Sim thread only.
  Options options_;  // the scene's (options_of) and the coupling of the mode; the loop steps with them
  bool position_mode_ = false;  // options_.coupling is on (set_position) or off (set_force)
  CouplingOptions coupling_;    // the session's coupling, used in position mode
  // What the loop keeps for the model it steps (made with it; for a cloud that follows the
  // tool, one per cloud, made on the refocus worker: core/refocus.h, CloudCompanion).
  struct Companion {
    explicit Companion(const State& rest_state) : rest(rest_state), checkpoint(rest_state) {}
    std::unique_ptr<StiffnessSource> stiffness;  // null when config_.contact_stiffness is false
    Checkpoint rest, checkpoint;                 // the rest state, the last good state
  };
  CloudCompanion make_companion(const Model& model, const State& rest) const;
  const Model* stepped_ = nullptr;  // the model the loop steps (the following cloud's current one)
  Companion* companion_ = nullptr;  // stepped_'s
  CloudCompanion own_companion_;    // companion_ when the cloud does not follow the tool
  std::unique_ptr<State> state_;
  double divergence_bound_ = 0.0;  // m, see diverged() in sim_loop.cpp
  uint64_t stiffness_evaluations_retired_ = 0;  // by the companions of clouds swapped out
  std::vector<double> shown_force_;             // 3 x shown particles: show_contacts()' scratch, zero between
  std::vector<int> shown_touched_;              // its touched base particles (capacity: all)
  std::vector<unsigned char> shown_marked_;     // 1 for those in shown_touched_
  SnapshotBuffer::Writer frames_writer_;
  bool paused_ = false;
  uint64_t applied_seq_ = 0;
  int64_t ticks_since_recovery_ = -1;  // -1: never recovered

  // Created by the sim thread before phase ready, then RPC thread only.
  SnapshotBuffer::Reader frames_reader_;
  // Created by the sim thread before phase ready; offer_model() sim thread, the rest as
  // HapticRenderer says; stopped by stop().
  std::unique_ptr<HapticRenderer> haptic_;

  // Any thread (atomic).
  std::atomic<Phase> phase_{Phase::starting};
  std::atomic<bool> stop_{false};
  std::atomic<bool> want_positions_{false}, want_contacts_{false}, want_derived_{false};

  // The command queue: a bounded ring with one consumer, the sim thread. Producers
  // serialise on command_mutex_ and publish an entry by advancing commands_written_
  // (release); the sim thread takes every published entry without a lock (acquire)
  // and frees the slots by advancing commands_read_. A producer descheduled while it
  // holds the mutex therefore never delays a command already queued, and a command
  // is applied at the latest two ticks after the tick its enqueue() returned at.
  std::mutex command_mutex_;
  uint64_t next_seq_ = 1;                  // under command_mutex_
  std::vector<Command> command_ring_;      // kMaxQueuedCommands entries, sized once
  std::atomic<uint64_t> commands_written_{0};
  std::atomic<uint64_t> commands_read_{0};

  // Any thread, under job_mutex_ (job_done_: atomic).
  std::mutex job_mutex_;
  std::condition_variable job_cv_;
  uint32_t job_ticks_ = 0;
  bool job_pending_ = false;
  std::atomic<bool> job_done_{false};

  // Written by the sim thread, read by any thread (atomic; the histograms are lock-free).
  std::atomic<int64_t> ticks_{0};
  std::atomic<int64_t> start_ns_{0}, last_tick_ns_{0};
  std::atomic<int64_t> stepping_ns_{0};
  std::atomic<uint64_t> deadline_misses_{0}, skipped_ticks_{0}, frames_published_{0}, frames_coalesced_{0};
  std::atomic<uint64_t> misses_late_start_{0}, misses_long_step_{0}, watchdog_rests_{0};
  std::atomic<uint32_t> blow_ups_{0};
  std::atomic<bool> realtime_priority_{false}, pinned_{false};
  std::atomic<uint64_t> stiffness_evaluations_{0};  // copied from the stiffness source at each publish
  std::atomic<int64_t> refocuses_{0}, refocuses_dropped_{0};
  std::atomic<bool> paused_flag_{false};
  std::atomic<int64_t> status_tick_{0};
  std::atomic<double> status_time_{0.0}, status_force_{0.0};
  std::atomic<bool> status_position_mode_{false};
  Histogram step_us_, lateness_us_;

  // Written by the sim thread, read by any thread, under text_mutex_.
  mutable std::mutex text_mutex_;
  std::string last_blow_up_, error_, last_refocus_drop_;
  int64_t last_blow_up_tick_ = -1;

  // The owner's thread (constructor, stop()).
  std::thread thread_;
};

}  // namespace palpate::server
