#pragma once
// What the simulation thread publishes after a tick, and the triple buffer that
// hands the newest one to the RPC thread without either side blocking.
// No KJ or Cap'n Proto here: the simulation thread includes this.
#include <atomic>
#include <cstdint>
#include <vector>

namespace palpate::server {

struct Snapshot {
  int64_t tick = 0;
  double sim_time = 0.0;               // s
  int64_t publish_ns = 0;              // CLOCK_MONOTONIC, ns
  double indenter[3] = {0, 0, 0};      // m
  double indenter_velocity = 0.0;      // m/s along z
  double contact_force = 0.0;          // N, on the indenter (positive up)
  double indentation = 0.0;            // m
  double force_command = 0.0;          // N
  uint64_t command_seq = 0;
  uint32_t recoveries = 0;
  bool has_positions = false;          // positions filled (someone wanted them)
  bool has_contacts = false;
  std::vector<float> positions;        // 3 n (capacity preallocated)
  std::vector<uint32_t> contact_nodes; // m <= n (capacity n)
  std::vector<float> contact_forces;   // 3 m (capacity 3 n)

  void reserve(int n) {
    positions.reserve(3 * static_cast<size_t>(n));
    contact_nodes.reserve(static_cast<size_t>(n));
    contact_forces.reserve(3 * static_cast<size_t>(n));
  }
};

// Single writer, single reader. The writer fills back() and publish()es it; the
// reader calls take() and reads front() until its next take(). Each side owns one
// slot; the third ("middle") is exchanged atomically, flagged when it is new.
class TripleBuffer {
 public:
  Snapshot& slot(int i) { return slots_[i]; }

  // Writer.
  Snapshot& back() { return slots_[back_]; }
  // Returns true if the reader had not taken the previous frame (it is replaced).
  bool publish() {
    const int previous = middle_.exchange(back_ | kNew, std::memory_order_acq_rel);
    back_ = previous & kIndex;
    return (previous & kNew) != 0;
  }

  // Reader: true if a newer frame became front().
  bool take() {
    if ((middle_.load(std::memory_order_acquire) & kNew) == 0) return false;
    front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return true;
  }
  const Snapshot& front() const { return slots_[front_]; }

 private:
  static constexpr int kNew = 4, kIndex = 3;
  Snapshot slots_[3];
  int back_ = 0;                // writer's
  int front_ = 1;               // reader's
  std::atomic<int> middle_{2};  // shared: index | kNew
};

}  // namespace palpate::server
