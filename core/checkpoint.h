#pragma once
// A saved copy of the fields of a State that carry over between steps (the
// Workspace is scratch), to return to the last good state after a failed health
// check (health.h). Storage is allocated once: saving and restoring allocate nothing.
#include <vector>

#include "core/state.h"

namespace palpate {

class Checkpoint {
 public:
  explicit Checkpoint(const State& s);
  void save(const State& s);
  // Physical fields and the health bookkeeping (energy budget); time, tick and the
  // force command stay the caller's. The restored state's last report is cleared.
  void restore(State& s) const;
  int64_t tick() const { return tick_; }

 private:
  Points position_, velocity_, contact_force_;
  Vec3 indenter_center_{0, 0, 0};
  double indenter_velocity_ = 0.0, indenter_contact_force_ = 0.0;
  std::vector<int> contact_index_;
  std::vector<double> contact_multiplier_;
  HealthMonitor health_;
  int64_t tick_ = 0;
};

}  // namespace palpate
