#include "core/checkpoint.h"

namespace palpate {

Checkpoint::Checkpoint(const State& s) : saved_(static_cast<const CarriedState&>(s)) {
  // Capacity for the largest contact set, so that later saves never reallocate.
  saved_.contact_index.reserve(s.contact_index.capacity());
  saved_.contact_normal_force.reserve(s.contact_normal_force.capacity());
}

// Copy-assignment of the vectors and Eigen arrays reuses their storage when the sizes
// fit (the same model), so neither direction allocates.
void Checkpoint::save(const State& s) { saved_ = static_cast<const CarriedState&>(s); }

void Checkpoint::restore(State& s) const {
  const double time = s.time;
  const Vec3 force_command = s.force_command;
  const int64_t tick = s.tick;
  static_cast<CarriedState&>(s) = saved_;
  s.time = time;
  s.tick = tick;
  s.force_command = force_command;
  s.health.report = {};
  // The ticks since each particle's last elastic update are the saved state's (multirate
  // symplectic Euler), counted back from the caller's clock.
  for (int64_t& last : s.elastic_update_tick) last += tick - saved_.tick;
}

}  // namespace palpate
