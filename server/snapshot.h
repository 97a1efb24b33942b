#pragma once
// What the simulation thread publishes after a tick, and the triple buffer that
// hands the newest one to the RPC thread without either side blocking.
// No KJ or Cap'n Proto here: the simulation thread includes this.
#include <atomic>
#include <cassert>
#include <concepts>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "core/contact_stiffness.h"
#include "core/types.h"
#include "protocol/local_model.h"

namespace palpate::server {

// A force near a point, linearised: F(x) = force + stiffness (x - origin) for
// |x - origin| <= valid_radius (wire LocalModel, docs/protocol.md; protocol/local_model.h,
// which the clients share): origin and force in m and N, stiffness dF/dx in N/m.
using LocalModel = protocol::LocalModel<Vec3, Mat3>;

struct Snapshot {
  int64_t tick = 0;
  double sim_time = 0.0;               // s
  int64_t publish_ns = 0;              // CLOCK_MONOTONIC, ns
  Vec3 tool_position{0, 0, 0};         // m
  Vec3 tool_velocity{0, 0, 0};         // m/s
  Vec3 tool_contact_force{0, 0, 0};    // N, of the body on the tool
  Vec3 force_command{0, 0, 0};         // N, force mode (zero in position mode)
  bool position_mode = false;
  Vec3 target{0, 0, 0};                // m, device position (position mode)
  Vec3 render_force{0, 0, 0};          // N, for the device (wire Frame.renderForce)
  bool force_saturated = false;
  LocalModel contact_model, render_model;
  // Server-side only (not on the wire): what contact_model was made from, the tool's
  // contact state and the newest contact stiffness (server/local_model.h
  // contact_model_now), so a study can render a frame with another step's stiffness.
  bool tool_touching = false;          // the state has particles in contact
  LocalContactModel stiffness_source;  // tick -1: none yet
  double indentation = 0.0;            // m
  uint64_t command_seq = 0;
  uint32_t recoveries = 0;
  int64_t refocuses_dropped = 0;  // a cloud that follows the tool: refocuses dropped so far
  uint64_t deadline_misses = 0;        // the session's so far
  bool has_positions = false;          // positions filled (someone wanted them)
  bool has_contacts = false;
  std::vector<float> positions;        // 3 n (capacity preallocated)
  std::vector<uint32_t> contact_nodes; // m <= n (capacity n)
  std::vector<float> contact_forces;   // 3 m (capacity 3 n)
  // The state's positions in double precision (3 x n, allocated by reserve()), filled when a
  // subscriber wants a field derived from them (Frame.displacementMagnitude, vonMises): the
  // RPC thread computes those from it, off the simulation thread.
  bool has_body_position = false;
  Points body_position;

  void reserve(int n) {
    body_position.setZero(3, n);
    positions.reserve(3 * static_cast<size_t>(n));
    contact_nodes.reserve(static_cast<size_t>(n));
    contact_forces.reserve(3 * static_cast<size_t>(n));
  }
};

// A single-writer, single-reader triple buffer of T, as two handles: the writer
// fills back() and publish()es it, the reader take()s the newest and reads front()
// until its next take(). Each handle owns one slot; the third ("middle") is
// exchanged atomically and flagged when it holds a frame the reader has not taken.
// Neither handle can reach the other's slot, so a frame is never written while it
// is read (no torn frames) and the reader only ever moves to newer frames.
//
//   TripleBuffer<Snapshot> frames([n](Snapshot& s) { s.reserve(n); });
//   give frames.writer to one thread, frames.reader to the other (move-only handles)
//
// Each handle belongs to one thread; they share the slots (freed with the last).
template <class T>
class TripleBuffer {
  struct Shared;

 public:
  class Writer {
   public:
    Writer() = default;  // empty until moved from a TripleBuffer
    Writer(Writer&&) noexcept = default;
    Writer& operator=(Writer&&) noexcept = default;
    T& back() {
      assert(shared_);
      return shared_->slots[back_];
    }
    // Makes back() the newest frame and gives the writer a free slot as back().
    // Returns true if the reader had not taken the previous frame (it is replaced).
    bool publish() {
      assert(shared_);
      const int previous = shared_->middle.exchange(back_ | kNew, std::memory_order_acq_rel);
      back_ = previous & kIndex;
      return (previous & kNew) != 0;
    }

   private:
    friend class TripleBuffer;
    explicit Writer(std::shared_ptr<Shared> s) : shared_(std::move(s)) {}
    std::shared_ptr<Shared> shared_;
    int back_ = 0;
  };

  class Reader {
   public:
    Reader() = default;  // empty until moved from a TripleBuffer
    Reader(Reader&&) noexcept = default;
    Reader& operator=(Reader&&) noexcept = default;
    // True if a newer frame became front().
    bool take() {
      assert(shared_);
      if ((shared_->middle.load(std::memory_order_acquire) & kNew) == 0) return false;
      front_ = shared_->middle.exchange(front_, std::memory_order_acq_rel) & kIndex;
      return true;
    }
    // The newest frame taken (before the first take(): the initial value).
    const T& front() const {
      assert(shared_);
      return shared_->slots[front_];
    }

   private:
    friend class TripleBuffer;
    explicit Reader(std::shared_ptr<Shared> s) : shared_(std::move(s)) {}
    std::shared_ptr<Shared> shared_;
    int front_ = 1;
  };

  Writer writer;
  Reader reader;

  // Three value-initialised slots, each passed once to prepare(T&) first (to
  // preallocate, so that neither side allocates later).
  template <class Prepare>
    requires std::invocable<Prepare&, T&>
  explicit TripleBuffer(Prepare&& prepare) : TripleBuffer(std::make_shared<Shared>()) {
    for (T& slot : writer.shared_->slots) prepare(slot);
  }
  TripleBuffer() : TripleBuffer([](T&) {}) {}

 private:
  static constexpr int kNew = 4, kIndex = 3;
  struct Shared {
    T slots[3] = {};
    std::atomic<int> middle{2};  // index | kNew
  };
  explicit TripleBuffer(std::shared_ptr<Shared> s) : writer(s), reader(s) {}
};

using SnapshotBuffer = TripleBuffer<Snapshot>;

}  // namespace palpate::server
