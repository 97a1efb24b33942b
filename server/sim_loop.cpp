#include "server/sim_loop.h"

#include <pthread.h>
#include <sched.h>
#include <sys/eventfd.h>
#include <sys/prctl.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include <spdlog/spdlog.h>

#include "core/health.h"
#include "core/hertz.h"
#include "core/indentation.h"
#include "core/step.h"
#include "core/thread_pool.h"
#include "server/deadlines.h"

namespace palpate::server {

namespace {

// The pressing force of the Hertz experiment's scalar fields (Frame.forceCommand,
// Status.forceCommand): N, -z of the force command.
double pressing_force(const State& state) { return -state.force_command[2]; }

// A finite state that is already running away: a particle or the indenter more
// than 10 diagonals of the body's bounding box from its reference (such values would
// also overflow the Float32 positions on the wire). One pass over 3 n doubles, no
// allocation.
double divergence_bound(const Model& model) {
  const Vec3 diagonal = model.rest_position.rowwise().maxCoeff() - model.rest_position.rowwise().minCoeff();
  return 10.0 * diagonal.norm();
}
bool diverged(const Model& model, const State& state, double bound) {
  const double worst = (state.position - model.rest_position).cwiseAbs().maxCoeff();
  const double indenter = (state.indenter_center - model.indenter_start).cwiseAbs().maxCoeff();
  return !(worst <= bound) || !(indenter <= bound);
}

}  // namespace

CouplingOptions clamp_to_device(CouplingOptions c, const DeviceLimits& device) {
  if (device.max_stiffness > 0.0) c.stiffness = std::min(c.stiffness, device.max_stiffness);
  if (device.max_damping > 0.0) c.damping = std::min(c.damping, device.max_damping);
  return c;
}

CouplingOptions default_coupling(const Model& model, const Options& opt, const DeviceLimits& device) {
  // The matrix (bulk) material, what is under the tool, even in a body with stiffer
  // inclusions (material.inclusions): the coupling is tuned to the surface it touches.
  const double mu = model.lame_mu, lambda = model.lame_lambda;
  const double young = mu * (3.0 * lambda + 2.0 * mu) / (lambda + mu);
  const double poisson = lambda / (2.0 * (lambda + mu));
  const double R = model.indenter_radius;
  CouplingOptions c;
  c.stiffness = 2.0 * hertz::effective_modulus(young, poisson) * std::sqrt(R * (R / 5.0));
  c = clamp_to_device(c, device);
  c.damping = 2.0 * std::sqrt(c.stiffness * opt.indenter_mass);
  return clamp_to_device(c, device);
}

// ---------------------------------------------------------------------------
// Simulation

Simulation::Simulation(SimConfig config, ScenePreparer prepare)
    : config_(std::move(config)), prepare_(std::move(prepare)) {
  start();
}

Simulation::Simulation(SimConfig config, Scene scene) : config_(std::move(config)), scene_(std::move(scene)) {
  start();
}

void Simulation::start() {
  wake_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) throw std::runtime_error(std::string("eventfd: ") + std::strerror(errno));
  command_ring_.resize(kMaxQueuedCommands);
  thread_ = std::thread([this] { run(); });
}

Simulation::~Simulation() {
  stop();
  if (wake_fd_ >= 0) close(wake_fd_);
}

void Simulation::cancel() {
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    stop_.store(true);
  }
  job_cv_.notify_all();
}

void Simulation::stop() {
  cancel();
  if (thread_.joinable()) thread_.join();
  haptic_.reset();  // no wake-ups after stop()
}

uint64_t Simulation::enqueue(CommandType type, const Vec3& value) {
  std::lock_guard<std::mutex> lock(command_mutex_);
  const uint64_t written = commands_written_.load(std::memory_order_relaxed);
  if (written - commands_read_.load(std::memory_order_acquire) >= kMaxQueuedCommands)
    return 0;  // refused: nothing queued, no number used
  const uint64_t seq = next_seq_++;
  command_ring_[written % kMaxQueuedCommands] = {type, value, seq};
  commands_written_.store(written + 1, std::memory_order_release);
  if (type == CommandType::set_position && haptic_) haptic_->offer_device(value, seq);  // rendered at once
  return seq;
}

void Simulation::request_steps(uint32_t n) {
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    job_ticks_ = n;
    job_pending_ = true;
  }
  job_cv_.notify_all();
}

void Simulation::notify() {
  const uint64_t one = 1;
  [[maybe_unused]] const ssize_t r = write(wake_fd_, &one, sizeof one);  // never blocks (EFD_NONBLOCK)
}

SimCounters Simulation::counters() const {
  SimCounters c;
  c.ticks = ticks_.load(std::memory_order_relaxed);
  const int64_t start = start_ns_.load(std::memory_order_relaxed);
  const int64_t last = last_tick_ns_.load(std::memory_order_relaxed);
  c.elapsed_s = start > 0 ? (config_.headless ? last - start : now_ns() - start) * 1e-9 : 0.0;
  c.stepping_s = stepping_ns_.load(std::memory_order_relaxed) * 1e-9;
  c.deadline_misses = deadline_misses_.load(std::memory_order_relaxed);
  c.skipped_ticks = skipped_ticks_.load(std::memory_order_relaxed);
  c.frames_published = frames_published_.load(std::memory_order_relaxed);
  c.frames_coalesced = frames_coalesced_.load(std::memory_order_relaxed);
  c.blow_ups = blow_ups_.load(std::memory_order_relaxed);
  c.realtime_priority = realtime_priority_.load(std::memory_order_relaxed);
  c.pinned = pinned_.load(std::memory_order_relaxed);
  c.misses_late_start = misses_late_start_.load(std::memory_order_relaxed);
  c.misses_long_step = misses_long_step_.load(std::memory_order_relaxed);
  c.stiffness_evaluations = stiffness_evaluations_.load(std::memory_order_relaxed);
  c.watchdog_rests = watchdog_rests_.load(std::memory_order_relaxed);
  c.refocuses = refocuses_.load(std::memory_order_relaxed);
  c.refocuses_dropped = refocuses_dropped_.load(std::memory_order_relaxed);
  c.step_us = step_us_.summary();
  c.lateness_us = lateness_us_.summary();
  if (phase() == Phase::ready && haptic_) c.haptic = haptic_->counters();
  return c;
}

SimStatus Simulation::status() const {
  SimStatus s;
  s.phase = phase();
  s.paused = paused_flag_.load(std::memory_order_relaxed);
  s.tick = status_tick_.load(std::memory_order_relaxed);
  s.sim_time = status_time_.load(std::memory_order_relaxed);
  s.force_command = status_force_.load(std::memory_order_relaxed);
  s.position_mode = status_position_mode_.load(std::memory_order_relaxed);
  s.blow_ups = blow_ups_.load(std::memory_order_relaxed);
  std::lock_guard<std::mutex> lock(text_mutex_);
  s.last_blow_up = last_blow_up_;
  s.last_blow_up_tick = last_blow_up_tick_;
  s.error = error_;
  s.last_refocus_drop = last_refocus_drop_;
  return s;
}

// The start, stage by stage; a cancel() ends it between stages (build_model itself
// cannot be interrupted).
void Simulation::prepare_and_build() {
  auto check_cancelled = [this] {
    if (stop_.load()) throw std::runtime_error("session closed while starting");
  };
  if (prepare_) {
    scene_ = prepare_();
    prepare_ = nullptr;  // releases what it captured (the request)
  }
  check_cancelled();
  const int64_t t0 = now_ns();
  options_ = options_of(scene_);
  auto companion_maker = [this](const Model& model, const State& rest) { return make_companion(model, rest); };
  if (follows_tool(scene_)) {
    following_ = std::make_unique<FollowingModel>(scene_, std::nullopt, config_.refocus, !config_.headless,
                                                  companion_maker);
    stepped_ = &following_->model();
    shown_ = &following_->base_model();
    companion_ = static_cast<Companion*>(following_->companion());
  } else {
    model_ = std::make_unique<Model>(build_model(scene_));
    stepped_ = shown_ = model_.get();
  }
  check_cancelled();
  initial_options_ = options_;
  coupling_ = config_.coupling.stiffness > 0.0 ? clamp_to_device(config_.coupling, config_.device)
                                               : default_coupling(*stepped_, options_, config_.device);
  initial_coupling_ = coupling_;
  state_ = std::make_unique<State>(make_state(*stepped_, options_));
  if (!following_) {
    own_companion_ = make_companion(*model_, *state_);
    companion_ = static_cast<Companion*>(own_companion_.get());
  }
  divergence_bound_ = divergence_bound(*shown_);
  if (companion_->stiffness) companion_->stiffness->prime(*state_);
  shown_force_.assign(3 * static_cast<size_t>(shown_->particle_count), 0.0);
  shown_touched_.reserve(static_cast<size_t>(shown_->particle_count));
  shown_marked_.assign(static_cast<size_t>(shown_->particle_count), 0);
  if (config_.haptic_rate_hz > 0.0 && !config_.headless)
    haptic_ = std::make_unique<HapticRenderer>(config_.haptic_rate_hz, config_.device.max_force, config_.spin_margin_us,
                                               config_.try_realtime, wake_fd_, config_.rpc_heartbeat);
  SnapshotBuffer frames([n = shown_->particle_count](Snapshot& s) { s.reserve(n); });
  frames_writer_ = std::move(frames.writer);
  frames_reader_ = std::move(frames.reader);
  build_seconds_ = (now_ns() - t0) * 1e-9;
  check_cancelled();
  if (!config_.reference_dir.empty()) {
    try {
      reference_ = find_reference(scene_, config_.reference_dir);
    } catch (const std::exception& e) {  // a reference is a display aid: never fails a session
      spdlog::warn("stored references in {}: {}", config_.reference_dir.string(), e.what());
    }
  }
}

void Simulation::run() {
  // Threads inherit the creator's policy (the RPC thread may be SCHED_FIFO): the start
  // and headless stepping run as ordinary threads; run_realtime() asks again.
  sched_param normal{};
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);
  try {
    prepare_and_build();
  } catch (const std::exception& e) {
    prepare_ = nullptr;
    {
      std::lock_guard<std::mutex> lock(text_mutex_);
      error_ = e.what();
    }
    phase_.store(Phase::failed, std::memory_order_release);
    notify();
    return;
  }
  status_force_.store(pressing_force(*state_), std::memory_order_relaxed);
  publish();  // the rest state, so a first frame exists
  phase_.store(Phase::ready, std::memory_order_release);
  notify();
  if (config_.headless) run_headless();
  else run_realtime();
}

void Simulation::run_headless() {
  // Headless stepping may use any core (it inherited the RPC thread's affinity).
  cpu_set_t all;
  CPU_ZERO(&all);
  for (int k = 0; k < CPU_SETSIZE && k < static_cast<int>(std::thread::hardware_concurrency()); ++k) CPU_SET(k, &all);
  pthread_setaffinity_np(pthread_self(), sizeof all, &all);
  configure_workers(false);
  start_ns_.store(now_ns(), std::memory_order_relaxed);
  last_tick_ns_.store(start_ns_.load(), std::memory_order_relaxed);
  for (;;) {
    uint32_t n = 0;
    {
      std::unique_lock<std::mutex> lock(job_mutex_);
      job_cv_.wait(lock, [this] { return stop_.load() || job_pending_; });
      if (stop_.load()) return;
      n = job_ticks_;
      job_pending_ = false;
    }
    for (uint32_t i = 0; i < n && !stop_.load(std::memory_order_relaxed); ++i) tick_once();
    last_tick_ns_.store(now_ns(), std::memory_order_relaxed);
    publish();
    job_done_.store(true, std::memory_order_release);
    notify();
  }
}

void Simulation::run_realtime() {
  prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0);
  if (config_.try_realtime) {
    sched_param param{};
    param.sched_priority = 10;
    if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &param) == 0) realtime_priority_.store(true);
  }
  if (config_.cpu >= 0) {  // a core of its own (the RPC thread and the workers stay off it)
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(config_.cpu, &one);
    if (pthread_setaffinity_np(pthread_self(), sizeof one, &one) == 0) pinned_.store(true);
  }
  configure_workers(true);
  // Touch the stack the steps will use, so that no page fault lands in a tick.
  {
    volatile char stack[256 * 1024];
    for (size_t k = 0; k < sizeof stack; k += 4096) stack[k] = 0;
  }
  Deadlines deadlines(static_cast<int64_t>(std::llround(1e9 / config_.rate_hz)),
                      static_cast<int64_t>(config_.spin_margin_us * 1000.0));
  if (realtime_priority_.load()) deadlines.give_way_to(config_.rpc_heartbeat);
  deadlines.start();
  start_ns_.store(now_ns(), std::memory_order_relaxed);
  while (!stop_.load(std::memory_order_relaxed)) {
    const int64_t tick_start = deadlines.wait();
    lateness_us_.add((tick_start - deadlines.deadline()) * 1e-3);

    if (tick_once()) publish();

    last_tick_ns_.store(now_ns(), std::memory_order_relaxed);
    const Deadlines::Outcome o = deadlines.finish(tick_start);
    if (o.watchdog_rest) watchdog_rests_.fetch_add(1, std::memory_order_relaxed);
    if (o.missed) {
      deadline_misses_.fetch_add(1, std::memory_order_relaxed);
      (o.late_start ? misses_late_start_ : misses_long_step_).fetch_add(1, std::memory_order_relaxed);
      skipped_ticks_.fetch_add(static_cast<uint64_t>(o.skipped), std::memory_order_relaxed);
    }
  }
}

// The workers of the step's pool (integrator.threads > 1; started by make_state on this
// thread, so with its policy and the RPC thread's affinity) follow the loop: a real-time
// loop's policy and priority (SCHED_FIFO 10 when granted), and when the loop is pinned to
// core c, worker t is pinned to core (c + t) mod cores -- on two cores, core 0, the RPC
// thread's (server/README.md, "Two threads for one session"). Headless: ordinary threads
// on any core. Each worker sets its own (the pool runs the task on every thread).
void Simulation::configure_workers(bool realtime) {
  ThreadPool* pool = state_->work.threads.pool.get();
  if (!pool) return;
  int policy = SCHED_OTHER;
  sched_param param{};
  if (realtime) pthread_getschedparam(pthread_self(), &policy, &param);
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const bool pin = realtime && pinned_.load();
  std::atomic<int> refused{0};
  pool->run([&](int t) {
    if (t == 0) return;
    if (pthread_setschedparam(pthread_self(), policy, &param) != 0) refused.fetch_add(1);
    cpu_set_t set;
    CPU_ZERO(&set);
    if (pin) CPU_SET((config_.cpu + t) % cores, &set);
    else
      for (int k = 0; k < cores && k < CPU_SETSIZE; ++k) CPU_SET(k, &set);
    if (pthread_setaffinity_np(pthread_self(), sizeof set, &set) != 0) refused.fetch_add(1);
  });
  if (refused.load() > 0) spdlog::warn("{} of the step's worker threads kept their policy or affinity", refused.load());
}

// Made on the thread that builds the model (the refocus worker for a cloud that follows the
// tool), never the loop's: the stiffness source starts its thread and sizes its buffers.
CloudCompanion Simulation::make_companion(const Model& model, const State& rest) const {
  auto c = std::make_shared<Companion>(rest);
  if (config_.contact_stiffness)
    c->stiffness = std::make_unique<StiffnessSource>(model, !config_.headless, config_.touch_lookahead);
  return c;
}

// After a refocus's swap: the state is the new cloud's. The new cloud's stiffness source
// starts from the old one's newest result (the same body, a moment ago); the checkpoint
// becomes this state. The old cloud and its companion are freed on the refocus worker.
void Simulation::take_new_cloud() {
  Companion* next = static_cast<Companion*>(following_->companion());
  if (companion_->stiffness) {
    next->stiffness->carry_over(companion_->stiffness->newest());
    stiffness_evaluations_retired_ += companion_->stiffness->evaluations();
  }
  companion_ = next;
  stepped_ = &following_->model();
  companion_->checkpoint.save(*state_);
  refocuses_.store(following_->refocus_count(), std::memory_order_relaxed);
}

bool Simulation::tick_once() {
  State& state = *state_;
  // Every command published so far, without a lock (see command_ring_ in sim_loop.h).
  const uint64_t published = commands_written_.load(std::memory_order_acquire);
  const uint64_t first_unread = commands_read_.load(std::memory_order_relaxed);
  for (uint64_t k = first_unread; k != published; ++k) {
    const Command& c = command_ring_[k % kMaxQueuedCommands];
    switch (c.type) {
      case CommandType::set_force:
        state.force_command = c.value;
        set_position_mode(false);
        break;
      case CommandType::set_position:
        state.tool_target = c.value;
        state.force_command.setZero();
        set_position_mode(true);
        break;
      case CommandType::set_coupling:
        coupling_ = {c.value[0], c.value[1]};
        set_position_mode(position_mode_);
        break;
      case CommandType::reset: {
        companion_->rest.restore(state);
        companion_->checkpoint.save(state);
        state.time = 0.0;
        state.tick = 0;
        state.force_command = press_down(stepped_->initial_force_command);
        set_position_mode(false);
        if (companion_->stiffness) companion_->stiffness->invalidate();
        if (following_) following_->state_jumped("the session was reset");
        ticks_since_recovery_ = -1;
        break;
      }
      case CommandType::pause: paused_ = true; break;
      case CommandType::resume: paused_ = false; break;
    }
    applied_seq_ = c.seq;
  }
  commands_read_.store(published, std::memory_order_release);  // frees the slots for enqueue()
  const bool had_commands = published != first_unread;
  paused_flag_.store(paused_, std::memory_order_relaxed);
  status_force_.store(pressing_force(state), std::memory_order_relaxed);
  status_position_mode_.store(position_mode_, std::memory_order_relaxed);
  if (paused_ && !config_.headless) {
    if (had_commands) publish();  // let subscribers see a reset while paused
    return false;
  }

  const int64_t t0 = now_ns();
  if (following_) {
    if (following_->before_step(options_, state)) take_new_cloud();
    if (following_->dropped_count() != refocuses_dropped_.load(std::memory_order_relaxed)) {
      std::lock_guard<std::mutex> lock(text_mutex_);  // rare: a refocus dropped (logged by the RPC thread)
      last_refocus_drop_ = following_->last_error();
      refocuses_dropped_.store(following_->dropped_count(), std::memory_order_relaxed);
    }
  }
  if (config_.before_step_for_tests) config_.before_step_for_tests(state);  // TEST HOOK (empty in the server)
  const Model& model = *stepped_;
  const StepStatus status = step(model, options_, state);
  const int64_t t1 = now_ns();
  step_us_.add((t1 - t0) * 1e-3);
  stepping_ns_.fetch_add(t1 - t0, std::memory_order_relaxed);
  ticks_.fetch_add(1, std::memory_order_relaxed);
  if (ticks_since_recovery_ >= 0) ++ticks_since_recovery_;

  // A failed health check (health.h) or a state gone far away: back to the last good state.
  if (is_fault(status)) recover(describe(state.health.report));
  else if (diverged(model, state, divergence_bound_)) recover("diverged state (displacement beyond 10 box diagonals)");
  else if (config_.checkpoint_interval > 0 && state.tick % config_.checkpoint_interval == 0)
    companion_->checkpoint.save(state);
  return true;
}

// Force mode: the coupling off. Position mode: the session's coupling (docs/physics.md (2.6)).
void Simulation::set_position_mode(bool on) {
  position_mode_ = on;
  options_.coupling = on ? coupling_ : CouplingOptions{};
}

// Restores the last good state. A second blow-up soon after a recovery means the
// checkpoint itself was on its way out (or the command cannot be held): restore
// the rest state and the scene's initial force instead.
void Simulation::recover(const std::string& what) {
  const Model& model = *stepped_;
  State& state = *state_;
  blow_ups_.fetch_add(1, std::memory_order_relaxed);
  const bool again = ticks_since_recovery_ >= 0 && ticks_since_recovery_ <= 2 * config_.checkpoint_interval;
  std::string how;
  const double command = pressing_force(state);
  const bool position_mode = position_mode_;
  if (again) {
    companion_->rest.restore(state);
    companion_->checkpoint.save(state);
    state.force_command = press_down(model.initial_force_command);
    set_position_mode(false);
    status_force_.store(pressing_force(state), std::memory_order_relaxed);
    status_position_mode_.store(false, std::memory_order_relaxed);
    how = "restored the rest state and the scene's initial force (" + std::to_string(pressing_force(state)) +
          " N; the command was " +
          (position_mode ? std::string("a position, now back in force mode") : std::to_string(command) + " N") + ")";
  } else {
    companion_->checkpoint.restore(state);
    how = "restored the last checkpoint (every " + std::to_string(config_.checkpoint_interval) + " ticks)";
  }
  ticks_since_recovery_ = 0;
  if (companion_->stiffness) companion_->stiffness->invalidate();
  if (following_) following_->state_jumped("the state was recovered (" + what + ")");
  const std::string message = what + ": " + how;
  {
    std::lock_guard<std::mutex> lock(text_mutex_);
    last_blow_up_ = message;
    last_blow_up_tick_ = state.tick;
  }
  // Logged by the RPC thread when a frame's recoveries count rises (server/session.cpp): never here.
}

// The frame's local models (wire LocalModel): the contact force as a function of the
// tool's centre, and the rendered force as a function of the device position.
void Simulation::fill_local_models(Snapshot& s, const Vec3& contact_force) const {
  const State& state = *state_;
  static const LocalContactModel none = [] {
    LocalContactModel m;
    m.tick = -1;
    return m;
  }();
  s.tool_touching = !state.contact_index.empty();
  s.stiffness_source = companion_->stiffness ? companion_->stiffness->newest() : none;
  s.contact_model = contact_model_now(state.indenter_center, contact_force, s.tool_touching, s.stiffness_source);
  // The render model's radius in contact: half the model's smallest particle spacing.
  s.render_model = render_model(s.contact_model, position_mode_, state.tool_target, s.render_force,
                                options_.coupling, 0.5 * stepped_->min_spacing);
}

// The contact forces on the shown particles: the stepped model's own, or for a cloud that
// follows the tool, each particle's force shared out to the base particles by its weights in
// the base mesh (the total kept). No allocation: the scratch and the frame are sized once.
void Simulation::show_contacts(Snapshot& s) {
  const State& state = *state_;
  const size_t m = state.contact_index.size();
  if (!following_) {
    for (size_t c = 0; c < m; ++c) {
      s.contact_nodes.push_back(static_cast<uint32_t>(state.contact_index[c]));
      for (int a = 0; a < 3; ++a) s.contact_forces.push_back(static_cast<float>(state.contact_force(a, c)));
    }
    return;
  }
  const CloudTransfer& in_base = following_->base_weights();
  shown_touched_.clear();
  for (size_t c = 0; c < m; ++c) {
    const int i = state.contact_index[c];
    for (int k = in_base.offset[i]; k < in_base.offset[i + 1]; ++k) {
      const int b = in_base.source[k];
      double* f = &shown_force_[3 * static_cast<size_t>(b)];
      if (!shown_marked_[b]) {
        shown_marked_[b] = 1;
        shown_touched_.push_back(b);
      }
      for (int a = 0; a < 3; ++a) f[a] += in_base.weight[k] * state.contact_force(a, static_cast<Eigen::Index>(c));
    }
  }
  for (const int b : shown_touched_) {
    double* f = &shown_force_[3 * static_cast<size_t>(b)];
    s.contact_nodes.push_back(static_cast<uint32_t>(b));
    for (int a = 0; a < 3; ++a) {
      s.contact_forces.push_back(static_cast<float>(f[a]));
      f[a] = 0.0;
    }
    shown_marked_[b] = 0;
  }
}

void Simulation::publish() {
  const Model& model = *stepped_;
  const State& state = *state_;
  if (companion_->stiffness) {
    companion_->stiffness->offer(state);
    stiffness_evaluations_.store(stiffness_evaluations_retired_ + companion_->stiffness->evaluations(),
                                 std::memory_order_relaxed);
  }
  // The force a device is given: the contact force, and after a refocus's swap the fading
  // offset between the two clouds' forces (docs/physics.md (7.3)).
  const Vec3 contact_force =
      following_ ? Vec3(state.indenter_contact_force + following_->force_offset(state)) : state.indenter_contact_force;
  Snapshot& s = frames_writer_.back();
  s.tick = state.tick;
  s.sim_time = state.time;
  s.tool_position = state.indenter_center;
  s.tool_velocity = state.indenter_velocity;
  s.tool_contact_force = contact_force;
  s.force_command = state.force_command;
  s.position_mode = position_mode_;
  s.target = state.tool_target;
  // Position mode: the device feels the coupling's reaction, -(its force on the tool);
  // force mode: the contact force, as if the device held the tool rigidly.
  s.render_force = position_mode_ ? Vec3(-state.out.coupling_force) : contact_force;
  s.force_saturated = saturate(s.render_force, config_.device.max_force);
  fill_local_models(s, contact_force);
  s.indentation = indentation(model, state);
  s.command_seq = applied_seq_;
  s.recoveries = blow_ups_.load(std::memory_order_relaxed);
  s.refocuses_dropped = refocuses_dropped_.load(std::memory_order_relaxed);
  s.has_positions = config_.headless || want_positions_.load(std::memory_order_relaxed);
  s.has_contacts = config_.headless || want_contacts_.load(std::memory_order_relaxed);
  s.positions.clear();
  if (s.has_positions) {
    const int n = shown_->particle_count;
    s.positions.resize(3 * static_cast<size_t>(n));  // within the reserved capacity
    const double* p = state.position.data();
    for (size_t k = 0; k < s.positions.size(); ++k) s.positions[k] = static_cast<float>(p[k]);
  }
  // One copy of 3 n doubles into the preallocated slot (same size: no allocation).
  s.has_body_position = config_.headless || want_derived_.load(std::memory_order_relaxed);
  if (s.has_body_position) s.body_position = state.position.leftCols(shown_->particle_count);
  s.contact_nodes.clear();
  s.contact_forces.clear();
  if (s.has_contacts) show_contacts(s);
  s.publish_ns = now_ns();
  s.deadline_misses = deadline_misses_.load(std::memory_order_relaxed);
  if (haptic_) haptic_->offer_model(render_input_of(s));
  status_tick_.store(state.tick, std::memory_order_relaxed);
  status_time_.store(state.time, std::memory_order_relaxed);
  frames_published_.fetch_add(1, std::memory_order_relaxed);
  if (frames_writer_.publish()) frames_coalesced_.fetch_add(1, std::memory_order_relaxed);
  notify();
}

}  // namespace palpate::server
