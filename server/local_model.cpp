#include "server/local_model.h"

#include <pthread.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <spdlog/spdlog.h>

namespace palpate::server {

StiffnessSource::StiffnessSource(const Model& model, bool worker_thread, double touch_lookahead)
    : model_(model), threaded_(worker_thread), stiffness_(model, kRenderingStiffness) {
  newest_.tick = -1;
  stiffness_.set_touch_lookahead(touch_lookahead);
  if (threaded_) {
    input_ = make_state(model, Options{});  // sized once: later copies reuse the storage
    work_ = input_;                          // the worker's own copy, made before it starts
    thread_ = std::thread([this] { run(); });
  }
}

StiffnessSource::~StiffnessSource() {
  if (!threaded_) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void StiffnessSource::prime(const State& state) {
  if (!threaded_) return;
  // The worker waits for its first input (pending_ is false), so stiffness_ is ours here.
  newest_ = stiffness_.evaluate(model_, state);
  evaluations_.fetch_add(1, std::memory_order_relaxed);
}

void StiffnessSource::offer(const State& state) {
  if (!threaded_) {
    newest_ = stiffness_.evaluate(model_, state);
    evaluations_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock()) return;  // the worker is taking its input or writing a result: next tick
  if (result_fresh_) {
    if (result_generation_ == generation_) newest_ = result_;
    result_fresh_ = false;
  }
  if (!busy_ && !pending_) {
    input_ = state;  // CarriedState part; same sizes, no allocation
    input_generation_ = generation_;
    pending_ = true;
    lock.unlock();
    wake_.notify_one();
  }
}

void StiffnessSource::invalidate() {
  ++generation_;
  newest_ = LocalContactModel{};
  newest_.tick = -1;
  if (!threaded_) stiffness_.clear_warm_start();
}

void StiffnessSource::run() {
  // Below the loop (SCHED_FIFO 10 when granted, else an ordinary thread) and the RPC
  // thread: an idle-priority share of the machine.
  sched_param normal{};
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 19);
  CarriedState& work = work_;
  uint64_t warm_generation = 0;
  double seconds_out_of_contact = 0.0, seconds_in_contact = 0.0;  // averages of the evaluations' durations
  for (;;) {
    uint64_t generation = 0;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stop_ || pending_; });
      if (stop_) return;
      std::swap(work, input_);
      generation = input_generation_;
      pending_ = false;
      busy_ = true;
    }
    if (generation != warm_generation) {
      stiffness_.clear_warm_start();
      warm_generation = generation;
    }
    LocalContactModel result;
    // (2.22): the time a stiffness at first touch will serve, from the averages below.
    stiffness_.set_touch_lookahead(0.5 * seconds_out_of_contact + seconds_in_contact);
    const auto started = std::chrono::steady_clock::now();
    try {
      result = stiffness_.evaluate(model_, work);
    } catch (const std::exception& e) {  // a state that does not belong to the model: a bug
      spdlog::error("contact stiffness: {}", e.what());
      result = LocalContactModel{};
      result.tick = -1;
    }
    evaluations_.fetch_add(1, std::memory_order_relaxed);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    if (!result.reused) {  // a reused result took no time: it says nothing of the next evaluation's
      double& average = result.active_count > 0 ? seconds_in_contact : seconds_out_of_contact;
      average = average > 0.0 ? 0.75 * average + 0.25 * seconds : seconds;
    }
    // The worker's own thread (never the loop's): --log-level debug shows each evaluation.
    spdlog::debug("contact stiffness: tick {}, {} active, {} at first touch (lookahead {:.1f} ms), {} CG iterations, "
                  "{:.1f} ms{}",
                  result.tick, result.active_count, result.touch_count, 1e3 * stiffness_.touch_lookahead(),
                  result.cg_iterations, 1e3 * seconds, result.reused ? " (unchanged state: the last result)" : "");
    std::lock_guard<std::mutex> lock(mutex_);
    result_ = result;
    result_generation_ = generation;
    result_fresh_ = true;
    busy_ = false;
  }
}

LocalModel contact_model_now(const State& state, const LocalContactModel& newest) {
  return contact_model_now(state.indenter_center, state.indenter_contact_force, !state.contact_index.empty(), newest);
}

LocalModel contact_model_now(const Vec3& centre, const Vec3& contact_force, bool touching,
                             const LocalContactModel& newest) {
  LocalModel m;
  m.origin = centre;
  m.force = contact_force;
  m.stiffness_tick = newest.tick;
  if (newest.tick < 0) return m;
  const double moved = (centre - newest.origin).norm();
  const bool computed_touching = newest.active_count > 0;
  if (touching == computed_touching) {
    if (touching) m.stiffness = newest.stiffness;
    m.valid_radius = std::max(0.0, newest.valid_radius - moved);
  } else if (touching && newest.touch_count > 0) {
    m.stiffness = newest.touch_stiffness;  // computed before the touch, for it (2.20); radius: the floor
  }
  return m;
}

Mat3 passive_stiffness(const Mat3& K) {
  const Mat3 symmetric = 0.5 * (K + K.transpose());
  const Eigen::SelfAdjointEigenSolver<Mat3> eigen(symmetric);
  const Vec3 clipped = eigen.eigenvalues().cwiseMin(0.0);
  return eigen.eigenvectors() * clipped.asDiagonal() * eigen.eigenvectors().transpose();
}

LocalModel render_model(const LocalModel& contact, bool position_mode, const Vec3& target,
                        const Vec3& render_force, const CouplingOptions& coupling, double contact_floor) {
  LocalModel r = contact;
  r.stiffness = passive_stiffness(contact.stiffness);
  const bool touching = contact.force.squaredNorm() > 0.0;
  if (touching && contact.stiffness_tick >= 0) r.valid_radius = std::max(r.valid_radius, contact_floor);
  if (!position_mode) return r;
  r.origin = target;
  r.force = render_force;
  const double k = coupling.stiffness;
  // (P.1) with the passive contact stiffness: k I - K_c is then positive definite.
  const Mat3 series = (k * Mat3::Identity() - r.stiffness).inverse();
  r.stiffness = k > 0.0 ? passive_stiffness(k * series * r.stiffness) : Mat3::Zero();
  return r;
}

}  // namespace palpate::server
