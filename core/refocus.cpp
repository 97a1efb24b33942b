// The resolution that follows a moving tool: ask, build, shadow, swap (core/refocus.h;
// docs/physics.md §7, (7.3)).
#include "core/refocus.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "core/health.h"
#include "core/step.h"

namespace palpate {

namespace {

double ms_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

constexpr size_t kMaxRecords = 4096;

}  // namespace

bool follows_tool(const Scene& scene) {
  const DistributionSpec& d = scene.distribution;
  return d.type == DistributionType::mesh && d.refine.enabled() && !d.focus_given;
}

FollowingModel::FollowingModel(const Scene& scene, const std::optional<Vec3>& tool, const RefocusOptions& options,
                               bool background, CompanionFactory make_companion)
    : scene_(scene), options_(options), background_(background), make_companion_(std::move(make_companion)) {
  if (!follows_tool(scene))
    throw std::invalid_argument(scene.source +
                                ": a cloud that follows the tool needs a mesh distribution with \"refine\" and "
                                "without \"focus\" (body.distribution)");
  if (!(options.distance > 0)) throw std::invalid_argument("refocus distance must be > 0 m");
  if (options.settle_steps < 1) throw std::invalid_argument("refocus settle_steps must be >= 1");
  if (options.fade_steps < 0) throw std::invalid_argument("refocus fade_steps must be >= 0");
  if (!(options.latency >= 0)) throw std::invalid_argument("refocus latency must be >= 0 s");
  base_ = read_mesh(scene.distribution.mesh_file);
  base_cloud_ = mesh_cloud(base_);
  base_model_ = build_model(scene_, base_cloud_);
  aim_ = tool ? *tool : tool_centre(scene_, base_);
  Options rest_options = options_of(scene_);
  rest_options.integrator.threads = 1;  // the companion's rest state only (the caller's state has the caller's threads)
  current_ = make_cloud(aim_, rest_options, nullptr);
  expected_delay_ = std::max(options.latency, options.settle_steps * options_of(scene_).integrator.dt);
  records_.reserve(kMaxRecords);
  if (background_) worker_ = std::thread(&FollowingModel::worker_loop, this);
}

FollowingModel::~FollowingModel() {
  if (worker_.joinable()) {
    stop_.store(true, std::memory_order_release);
    signal();
    worker_.join();
  }
}

void FollowingModel::signal() {
  signal_.fetch_add(1, std::memory_order_release);
  signal_.notify_one();
}

// A cloud refined toward `tool`: its model, its weights in the base mesh, and the companion
// made from its rest state (returned in *rest when asked for).
std::unique_ptr<FollowingModel::Cloud> FollowingModel::make_cloud(const Vec3& tool, const Options& opt,
                                                                  std::unique_ptr<State>* rest) {
  auto c = std::make_unique<Cloud>();
  auto t = std::chrono::steady_clock::now();
  c->focus = refinement_focus(scene_, base_, tool);
  c->cloud = refined_mesh_cloud(scene_, base_, tool);
  c->refine_ms = ms_since(t);
  t = std::chrono::steady_clock::now();
  c->model = build_model(scene_, c->cloud);
  c->build_ms = ms_since(t);
  c->in_base = make_cloud_transfer(base_model_.rest_position, base_cloud_.tetrahedra, c->model.rest_position,
                                   c->cloud.tetrahedra);
  auto state = std::make_unique<State>(make_state(c->model, opt));
  c->at_ask = std::make_unique<Checkpoint>(*state);  // storage for the state at an ask: saving it allocates nothing
  if (make_companion_) c->companion = make_companion_(c->model, *state);
  if (rest) *rest = std::move(state);
  return c;
}

// Stage 2: the cloud refined toward aim_, its model, the transfer weights from the current
// cloud and the new cloud's State. The retired cloud and state of the last swap are freed here.
void FollowingModel::build_next() {
  retired_.reset();
  shadow_.reset();
  std::unique_ptr<State> rest;
  auto next = make_cloud(aim_, shadow_options_, &rest);
  const auto t = std::chrono::steady_clock::now();
  transfer_ = make_cloud_transfer(current_->model.rest_position, current_->cloud.tetrahedra, next->model.rest_position,
                                  next->cloud.tetrahedra);
  weights_ms_ = ms_since(t);
  shadow_ = std::move(rest);
  use_threads(next->model, shadow_options_, *shadow_);
  next_ = std::move(next);
}

void FollowingModel::save_at_ask(const State& state) {
  current_->at_ask->save(state);
  published_.store(0, std::memory_order_relaxed);  // the worker reads the ring only once shadowing
  save_again_ = false;
}

void FollowingModel::state_jumped(const std::string& why) {
  offset_tick_ = -1;
  checked_ = false;
  const int building = phase_.load(std::memory_order_acquire);
  if (building == kAsked || building == kBuilt) save_again_ = true;  // the replay starts from the jumped state
  int phase = kShadowing;
  if (background_) {
    if (phase_.compare_exchange_strong(phase, kDropping, std::memory_order_acq_rel)) {
      drop(why);
      signal();  // the worker sets kIdle when it has stopped
    }
  } else if (phase_.load(std::memory_order_relaxed) == kShadowing) {
    drop(why);
    phase_.store(kIdle, std::memory_order_release);
  }
}

bool FollowingModel::step_shadow(const ToolEntry& entry) {
  State& s = *shadow_;
  s.indenter_center = entry.center;
  s.indenter_velocity = entry.velocity;
  s.force_command = entry.force_command;
  s.tool_target = entry.tool_target;
  return !is_fault(step(next_->model, shadow_options_, s));
}

void FollowingModel::drop(const std::string& why) {
  ++dropped_count_;
  last_error_ = why;
}

bool FollowingModel::before_step(const Options& opt, State& state) {
  const int64_t tick = state.tick;
  int phase = phase_.load(std::memory_order_acquire);
  if (phase == kFailed) {
    drop(worker_error_);
    phase_.store(kIdle, std::memory_order_release);
    checked_ = false;
    return false;
  }
  if (phase == kIdle) {
    // Stage 1: due when the surface point under the tool is `distance` from the focus. The
    // nearest surface point is looked for only when the tool has moved a quarter of that.
    const Vec3 c = state.indenter_center;
    if (checked_ && (c - checked_at_).norm() < 0.25 * options_.distance) return false;
    checked_at_ = c;
    checked_ = true;
    if ((refinement_focus(scene_, base_, c) - current_->focus).norm() <= options_.distance) return false;
    aim_ = options_.lead ? Vec3(c + 1.5 * expected_delay_ * state.indenter_velocity) : c;
    ask_tick_ = tick;
    shadow_options_ = opt;
    shadow_options_.integrator.threads = 1;
    save_at_ask(state);  // the shadow will start from this state and replay the tool from here
    if (background_) {
      phase = kAsked;
      phase_.store(kAsked, std::memory_order_release);
      signal();
    } else {
      try {
        build_next();
      } catch (const std::exception& e) {
        drop(e.what());
        return false;
      }
      carry_due_tick_ = tick + std::lround(options_.latency / opt.integrator.dt);
      phase = kBuilt;
      phase_.store(kBuilt, std::memory_order_release);
    }
  }
  if (phase == kAsked || phase == kBuilt) {
    // A state that jumped, or a build longer than the ring: the replay starts again from here.
    if (save_again_ || published_.load(std::memory_order_relaxed) >= kRing) save_at_ask(state);
  }
  if (phase == kBuilt && (background_ || tick >= carry_due_tick_)) {
    // Stage 3 begins: the state saved at the ask carried to the new cloud (7.2); the shadow
    // replays the tool from there (the entries published since) and then keeps pace.
    const auto t = std::chrono::steady_clock::now();
    transfer_state(transfer_, current_->model, current_->at_ask->saved(), next_->model, *shadow_);
    carry_ms_ = ms_since(t);
    carry_tick_ = tick;
    consumed_.store(0, std::memory_order_relaxed);
    phase_.store(kShadowing, std::memory_order_release);
    phase = kShadowing;
  }
  if (phase != kShadowing && phase != kAsked && phase != kBuilt) return false;
  const int64_t published = published_.load(std::memory_order_relaxed);  // written by this thread only
  const int64_t consumed = phase == kShadowing ? consumed_.load(std::memory_order_acquire) : 0;
  if (phase == kShadowing && published >= options_.settle_steps && consumed == published) {
    // Stage 4: the shadow has caught up (the worker is idle: it steps only what is published).
    const Vec3 old_force = state.indenter_contact_force, new_force = shadow_->indenter_contact_force;
    copy_tool(state, *shadow_);
    shadow_->health = state.health;
    std::swap(state, *shadow_);
    std::swap(state.work.threads.pool, shadow_->work.threads.pool);  // the caller's threads stay the caller's
    offset_ = old_force - new_force;
    offset_tick_ = tick;
    expected_delay_ = (tick - ask_tick_) * opt.integrator.dt;
    if (records_.size() < kMaxRecords) {
      RefocusRecord r;
      r.ask_tick = ask_tick_;
      r.carry_tick = carry_tick_;
      r.swap_tick = tick;
      r.focus = next_->focus;
      r.particles_before = current_->model.particle_count;
      r.particles_after = next_->model.particle_count;
      r.exact = transfer_.exact;
      r.force_offset = offset_;
      r.refine_ms = next_->refine_ms;
      r.build_ms = next_->build_ms;
      r.weights_ms = weights_ms_;
      r.carry_ms = carry_ms_;
      records_.push_back(r);
    }
    ++refocus_count_;
    retired_ = std::move(current_);
    current_ = std::move(next_);
    checked_ = false;
    phase_.store(kIdle, std::memory_order_release);
    return true;
  }
  if (phase == kShadowing && published - consumed >= kRing) {
    // The worker fell a whole ring behind: the refocus is dropped (asked again later).
    int expected = kShadowing;
    if (phase_.compare_exchange_strong(expected, kDropping, std::memory_order_acq_rel)) {
      drop("the shadow fell " + std::to_string(kRing) + " steps behind the current cloud");
      signal();  // the worker sets kIdle when it has stopped
    }
    return false;
  }
  ring_[published % kRing] = {state.indenter_center, state.indenter_velocity, state.force_command, state.tool_target};
  published_.store(published + 1, std::memory_order_release);
  if (phase != kShadowing) return false;  // recorded for the replay
  if (background_) {
    signal();
  } else {
    for (int64_t k = consumed; k <= published; ++k)  // the replay since the ask, then this tick's step
      if (!step_shadow(ring_[k % kRing])) {
        drop("the shadow failed a health check: " + describe(shadow_->health.report));
        phase_.store(kIdle, std::memory_order_release);
        checked_ = false;
        return false;
      }
    consumed_.store(published + 1, std::memory_order_release);
  }
  return false;
}

Vec3 FollowingModel::force_offset(const State& state) const {
  const int64_t n = state.tick - offset_tick_;
  if (offset_tick_ < 0 || n < 1 || n > options_.fade_steps) return Vec3::Zero();
  // (7.3): the offset fades linearly, to zero after fade_steps steps.
  return offset_ * (1.0 - static_cast<double>(n) / (options_.fade_steps + 1));
}

void FollowingModel::worker_loop() {
  while (true) {
    const uint32_t seen = signal_.load(std::memory_order_acquire);
    if (stop_.load(std::memory_order_acquire)) return;
    int phase = phase_.load(std::memory_order_acquire);
    if (phase == kAsked) {
      try {
        build_next();
        phase_.store(kBuilt, std::memory_order_release);
      } catch (const std::exception& e) {
        worker_error_ = e.what();
        phase_.store(kFailed, std::memory_order_release);
      }
      continue;
    }
    if (phase == kShadowing) {
      const int64_t c = consumed_.load(std::memory_order_relaxed);  // written by this thread only
      if (published_.load(std::memory_order_acquire) > c) {
        if (!step_shadow(ring_[c % kRing])) {
          worker_error_ = "the shadow failed a health check: " + describe(shadow_->health.report);
          if (!phase_.compare_exchange_strong(phase, kFailed, std::memory_order_acq_rel))
            phase_.store(kIdle, std::memory_order_release);  // the caller had dropped it already
          continue;
        }
        consumed_.store(c + 1, std::memory_order_release);
        continue;
      }
    }
    if (phase == kDropping) {  // dropped by the caller: this thread has stopped stepping
      phase_.store(kIdle, std::memory_order_release);
      continue;
    }
    signal_.wait(seen, std::memory_order_acquire);
  }
}

}  // namespace palpate
