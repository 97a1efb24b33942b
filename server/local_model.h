#pragma once
// The local models a frame carries for a haptic servo loop faster than the tick
// rate (docs/protocol.md, "The local contact model"): the force on a point near
// an origin, linearised, F(x) = F0 + K (x - x0), valid within a radius.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>

#include "core/contact_stiffness.h"
#include "core/model.h"
#include "core/options.h"
#include "core/state.h"
#include "core/types.h"
#include "server/snapshot.h"

namespace palpate::server {

// The contact stiffness for the frames (core/contact_stiffness.h). Real time: a worker
// thread (SCHED_OTHER, nice 19: it takes only what the loop and the RPC thread leave)
// evaluates the newest state the loop handed it, over as many ticks as that takes;
// the loop hands over a copy only when the worker is idle and never waits for it.
// Headless: evaluated on the session's thread at every offer (deterministic).
// Session-thread methods are offer(), invalidate() and newest().
class StiffnessSource {
 public:
  // touch_lookahead (s): of the stiffness at first touch (ContactStiffness::set_touch_lookahead,
  // docs/physics.md (2.22)), headless. The worker sets its own before each evaluation: how
  // long a stiffness at first touch serves, half an evaluation out of contact (the one
  // under way at the touch) and one in contact (the first after it), from the averages
  // of its own durations.
  StiffnessSource(const Model& model, bool worker_thread, double touch_lookahead = 0.0);
  ~StiffnessSource();  // joins the worker
  StiffnessSource(const StiffnessSource&) = delete;
  StiffnessSource& operator=(const StiffnessSource&) = delete;

  // Before the loop's first offer(), on the session's thread: evaluates `state` there and
  // then (the first evaluation is a cold one, a tenth of a second on the graded cube), so
  // a real-time session's first frames already carry a stiffness (and the worker starts
  // warm). Headless, nothing: every offer() evaluates.
  void prime(const State& state);
  // The state just stepped (and published).
  void offer(const State& state);
  // The state jumped (reset, a recovered blow-up): results and warm starts from before
  // are dropped.
  void invalidate();
  // The newest result of another cloud's source of the same body, at a refocus's swap
  // (core/refocus.h): it serves (origin, radius and tick its own) until this source has
  // evaluated the new cloud.
  void carry_over(const LocalContactModel& newest) { newest_ = newest; }
  // The newest result taken (tick -1: none since the start or the last invalidate()).
  const LocalContactModel& newest() const { return newest_; }
  uint64_t evaluations() const { return evaluations_.load(std::memory_order_relaxed); }

 private:
  void run();

  const Model& model_;
  const bool threaded_;
  ContactStiffness stiffness_;  // the worker's (or, headless, the session thread's)
  LocalContactModel newest_;    // session thread
  uint64_t generation_ = 0;     // session thread: bumped by invalidate()

  CarriedState work_;  // the worker's state (swapped with input_ under mutex_)

  std::mutex mutex_;  // guards the members below
  std::condition_variable wake_;
  CarriedState input_;
  uint64_t input_generation_ = 0;
  bool pending_ = false, busy_ = false, stop_ = false;
  LocalContactModel result_;
  uint64_t result_generation_ = 0;
  bool result_fresh_ = false;

  std::atomic<uint64_t> evaluations_{0};
  std::thread thread_;  // last: started when everything above exists
};

// The frame's contact model at `state` from the newest stiffness: origin and force are
// the state's; the stiffness is the newest result's when it was computed with contact
// and the state is still in contact, or its stiffness at first touch (docs/physics.md
// (2.20)) when it was computed out of contact and the state now touches (else zero);
// the valid radius shrinks by how far the tool moved since (never below zero; zero
// after a touch, where render_model's floor applies).
// The nearest passive stiffness to K: its symmetric part with every positive eigenvalue
// set to zero (docs/protocol.md (P.2)). The discrete contact's K may have one: pushed
// sideways off a particle, the frictionless sphere is pushed further (docs/physics.md
// (2.13)); rendered, it would put energy into the device.
Mat3 passive_stiffness(const Mat3& K);

LocalModel contact_model_now(const State& state, const LocalContactModel& newest);
// The same rule for a tool at `centre` with `contact_force`, touching or not.
LocalModel contact_model_now(const Vec3& centre, const Vec3& contact_force, bool touching,
                             const LocalContactModel& newest);

// renderForce (Frame.renderForce) as a function of the device position, from the
// contact model of the tool. Position mode, with the tool quasi-static over a servo
// period (its inertia and the coupling's damping neglected): the tool sits where the
// coupling balances the contact, k (x_d - c) + F_c(c) = 0, so a device displacement
// dx_d moves it by dc = (k I - K_c)^-1 k dx_d and the rendered force -k (x_d - c)
// changes by
//     dF_render = k (k I - K_c)^-1 K_c dx_d,                (docs/protocol.md (P.1))
// the coupling and the contact in series; the tool moves no further than the device
// where K_c is negative semi-definite, so the contact model's radius serves. Force
// mode: the contact model itself, about the tool's centre. Either way the stiffness is
// then made passive (passive_stiffness): a device must not be handed an active element.
// The radius: in contact at least `contact_floor` (docs/protocol.md: the force is
// continuous where the active set changes, only K jumps, so the strict first-order
// radius of the contact model, often micrometres, would throw the model away); out of
// contact the contact model's (the distance to the body).
LocalModel render_model(const LocalModel& contact, bool position_mode, const Vec3& target,
                        const Vec3& render_force, const CouplingOptions& coupling, double contact_floor);

}  // namespace palpate::server
