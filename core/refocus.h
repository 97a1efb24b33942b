#pragma once
// The resolution that follows a moving tool (docs/physics.md §7, "Refocusing while the tool
// moves"). A FollowingModel holds the model of a cloud refined toward the tool (a scene whose
// mesh distribution has "refine" and no "focus": core/mesh_refinement.h) and refocuses it as
// the tool moves, in four stages:
//
//  1. ask: when the point of the body's surface nearest the tool is more than
//     RefocusOptions::distance from the current cloud's focus, a cloud refined toward where
//     the tool is heading is asked for (aimed ahead along its velocity by 1.5 times the
//     expected delay to the swap, so that the tool passes the new focus midway between this
//     swap and the next);
//  2. build: the refinement, the model, the transfer weights (core/cloud_transfer.h) and the
//     new cloud's State, on a worker thread (background) or on the caller's (inline);
//  3. shadow: the caller's state as it was at the ask (a checkpoint saved then) is carried to
//     the new cloud (7.2) once it is built, and the new cloud is stepped with the current one's
//     tool (its centre, velocity, command and target before each step, recorded from the ask
//     on) through the ticks since the ask, as fast as it can, then beside the current one:
//     settle_steps steps at least and until it has caught up. Its transient stays behind it,
//     and the build's time is replayed rather than waited out after it (the swap comes
//     max(build, settle_steps) after the ask, not their sum);
//  4. swap: at a tick boundary the shadow's body becomes the caller's state, the tool staying
//     the current one's; the difference of the contact forces of the two clouds at that
//     instant is handed out as an offset that fades linearly over fade_steps (7.3), so the
//     force a device is given does not jump.
//
// Inline mode with a fixed latency depends on the trajectory only (the ask, carry and swap
// ticks and every number are those of a rerun). Background mode carries as soon as the worker
// has built and swaps as soon as the shadow has caught up, so its ticks depend on the machine;
// the caller's thread then only copies the tool into a ring each tick and, once per refocus,
// saves its state into a checkpoint at the ask (a copy), carries that (a sparse product) and
// swaps pointers: it allocates nothing, and frees nothing (the retired cloud is freed on the
// worker).
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/checkpoint.h"
#include "core/cloud_transfer.h"
#include "core/mesh_reader.h"
#include "core/model.h"
#include "core/node_cloud.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"

namespace palpate {

struct RefocusOptions {
  double distance = 0.0005;  // m: refocus when the surface point under the tool is this far from the focus
  int settle_steps = 160;    // shadow steps before the swap, at least (docs/physics.md §7: 40 still rings)
  int fade_steps = 40;       // steps over which the swap's force offset fades to zero (7.3); 0: none
  bool lead = true;          // aim ahead along the tool's velocity (else at the tool)
  // Inline mode: the time from an ask to the carry, s (the build's wall time it stands for).
  // Background mode: the carry follows the build; this only sets the delay to the swap the
  // first ask's aim expects (later asks expect the last refocus's measured delay).
  double latency = 0.2;
};

// One refocus, as the caller's thread saw it.
struct RefocusRecord {
  int64_t ask_tick = 0, carry_tick = 0, swap_tick = 0;  // State::tick at each stage
  Vec3 focus{0, 0, 0};                                 // m, the new cloud's focus
  int particles_before = 0, particles_after = 0;
  int exact = 0;                     // new particles that coincide with an old one (CloudTransfer::exact)
  Vec3 force_offset{0, 0, 0};        // N, old minus new contact force on the tool at the swap
  double refine_ms = 0, build_ms = 0, weights_ms = 0;  // on the worker (or the caller, inline)
  double carry_ms = 0;               // transfer_state on the caller's thread
};

// A scene whose cloud follows the tool: a mesh distribution with "refine" and without "focus".
bool follows_tool(const Scene& scene);

// What a caller keeps beside each cloud (a session: its contact-stiffness worker and its
// checkpoints, all sized for that cloud's model), made by the caller's factory from the
// cloud's model and its rest state (make_state) on the thread that builds the cloud (the
// worker in background mode: never the real-time thread), and freed with the cloud, before
// its model. What the factory throws drops the refocus like a failed build.
using CloudCompanion = std::shared_ptr<void>;
using CompanionFactory = std::function<CloudCompanion(const Model& model, const State& rest)>;

class FollowingModel {
 public:
  // The model refined toward the tool at `tool` (m; none: where the scene starts it,
  // tool_centre), the scene's base mesh read from its file. Throws std::invalid_argument
  // unless follows_tool(scene). background: build and shadow on a worker thread of its own.
  // make_companion (optional): see CloudCompanion; called here for the first cloud too.
  FollowingModel(const Scene& scene, const std::optional<Vec3>& tool, const RefocusOptions& options,
                 bool background, CompanionFactory make_companion = {});
  ~FollowingModel();  // stops and joins the worker (an unfinished refocus is dropped)
  FollowingModel(const FollowingModel&) = delete;
  FollowingModel& operator=(const FollowingModel&) = delete;

  // The current cloud's model (a different object after a swap) and its cloud.
  const Model& model() const { return current_->model; }
  const NodeCloud& cloud() const { return current_->cloud; }
  const Vec3& focus() const { return current_->focus; }
  // The companion the factory made for the current cloud (null without a factory).
  void* companion() const { return current_->companion.get(); }

  // The base mesh's own model (unrefined): what a viewer is shown, one topology whatever the
  // cloud. Its particles are the first base_model().particle_count particles of every cloud,
  // at the same reference positions (refine_mesh keeps the base's vertices and indices).
  const Model& base_model() const { return base_model_; }
  // The current cloud located in the base mesh (7.2): for each particle of model(), its
  // barycentric weights over base particles (the first terms, offset/source/weight). A force
  // on a particle shown on the base shares out by these weights: the total is kept.
  const CloudTransfer& base_weights() const { return current_->in_base; }

  // The caller's state jumped (a reset, a recovery to a checkpoint): a refocus already carried
  // is dropped (its shadow follows a state that no longer is; counted in dropped_count() with
  // `why`), and the fading offset of the last swap is cancelled. A cloud being built is kept:
  // the state saved at the ask is saved again at the next call, and the tool recorded from there.
  void state_jumped(const std::string& why);

  // Call before each step of model() with `state` (its tool command and target already set
  // for the step). Asks, carries, feeds the shadow and swaps when their time has come. Returns
  // true when it swapped: `state` then belongs to the new model(), which the step must use.
  bool before_step(const Options& opt, State& state);

  // The swap's fading offset (7.3) to add to state.indenter_contact_force after a step: what
  // a device is given. Zero outside the fade_steps steps after a swap.
  Vec3 force_offset(const State& state) const;

  // Every refocus so far (up to the first 4096; refocus_count() counts them all), and the
  // refocuses dropped: a shadow that failed a health check, a build that threw, or a worker
  // that fell a whole ring behind. last_error() says why the last one was dropped.
  const std::vector<RefocusRecord>& refocuses() const { return records_; }
  int64_t refocus_count() const { return refocus_count_; }
  int64_t dropped_count() const { return dropped_count_; }
  const std::string& last_error() const { return last_error_; }
  bool pending() const { return phase_.load(std::memory_order_acquire) != kIdle; }
  // Background mode: the worker is building a cloud; the tool states published to the shadow
  // that it has not stepped yet (0 when no shadow runs). A loop that waits for both to clear
  // after each step runs in lockstep with the worker: it computes what inline mode does.
  bool building() const { return phase_.load(std::memory_order_acquire) == kAsked; }
  int64_t shadow_lag() const {
    if (phase_.load(std::memory_order_acquire) != kShadowing) return 0;
    return published_.load(std::memory_order_acquire) - consumed_.load(std::memory_order_acquire);
  }

 private:
  struct Cloud {
    NodeCloud cloud;
    Model model;
    std::unique_ptr<Checkpoint> at_ask;  // the caller's state at the ask of a refocus from this cloud
    Vec3 focus{0, 0, 0};
    double refine_ms = 0, build_ms = 0;
    CloudTransfer in_base;     // see base_weights()
    CloudCompanion companion;  // last: freed before the model it was made for
  };
  // The tool before one step of the current model: what the shadow's step starts from.
  struct ToolEntry {
    Vec3 center, velocity, force_command, tool_target;
  };
  // Tool entries the shadow may fall behind (from the ask: a build that takes longer has the
  // state at the ask saved again, and the replay starts from there).
  static constexpr int kRing = 1024;

  enum Phase : int { kIdle, kAsked, kBuilt, kShadowing, kDropping, kFailed };  // phase_, see worker_loop

  std::unique_ptr<Cloud> make_cloud(const Vec3& tool, const Options& opt, std::unique_ptr<State>* rest);
  void save_at_ask(const State& state);  // the replay starts at this tick
  void build_next();               // stage 2 (worker or inline)
  bool step_shadow(const ToolEntry& entry);  // one shadow step; false: it failed
  void worker_loop();
  void signal();
  void drop(const std::string& why);

  Scene scene_;
  TetMesh base_;
  NodeCloud base_cloud_;
  Model base_model_;
  RefocusOptions options_;
  bool background_;
  CompanionFactory make_companion_;
  std::unique_ptr<Cloud> current_, next_, retired_;
  std::unique_ptr<State> shadow_;
  CloudTransfer transfer_;
  double weights_ms_ = 0;
  Options shadow_options_;

  // The caller's bookkeeping.
  Vec3 aim_{0, 0, 0};
  Vec3 checked_at_{0, 0, 0};       // the tool's centre when the focus under it was last computed
  bool checked_ = false;
  double expected_delay_ = 0.2;   // s from an ask to the swap (the last refocus's)
  int64_t ask_tick_ = 0, carry_tick_ = 0, carry_due_tick_ = 0;
  bool save_again_ = false;        // the state jumped while a cloud was built: save it again
  double carry_ms_ = 0;
  Vec3 offset_{0, 0, 0};
  int64_t offset_tick_ = -1;
  std::vector<RefocusRecord> records_;
  int64_t refocus_count_ = 0, dropped_count_ = 0;
  std::string last_error_;
  std::string worker_error_;  // written by the worker before it sets kFailed

  // Shared with the worker.
  ToolEntry ring_[kRing];
  alignas(64) std::atomic<int> phase_{kIdle};
  alignas(64) std::atomic<int64_t> published_{0};  // tool entries written since the state was saved
  alignas(64) std::atomic<int64_t> consumed_{0};   // shadow steps done since the carry
  alignas(64) std::atomic<uint32_t> signal_{0};
  std::atomic<bool> stop_{false};
  std::thread worker_;
};

}  // namespace palpate
