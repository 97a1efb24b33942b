#pragma once
// A saved copy of the CarriedState of a State (state.h: what one step hands to the
// next), to return to an earlier state: the last good state after a failed health
// check (health.h), the rest state of a session, a rejected step of the static
// solve, a benchmark's starting point. Storage is allocated once: after the first
// save, saving and restoring a State of the same model allocate nothing.
#include <cstdint>

#include "core/state.h"

namespace palpate {

class Checkpoint {
 public:
  explicit Checkpoint(const State& s);
  void save(const State& s);
  // Everything carried (positions, velocities, indenter, contact set, health
  // bookkeeping) except the clock and the input: time, tick and the force command
  // stay the caller's (a session's tick keeps running through a recovery, and the
  // command is what the user last asked for); the ticks of the particles' last elastic
  // updates move with the clock. The restored state's last health report is cleared.
  void restore(State& s) const;
  int64_t tick() const { return saved_.tick; }
  const CarriedState& saved() const { return saved_; }

 private:
  CarriedState saved_;
};

}  // namespace palpate
