#include "core/checkpoint.h"

namespace palpate {

Checkpoint::Checkpoint(const State& s) {
  contact_index_.reserve(s.contact_index.capacity());
  contact_multiplier_.reserve(s.contact_multiplier.capacity());
  save(s);
}

void Checkpoint::save(const State& s) {
  position_ = s.position;  // same shape each time: Eigen copies without reallocating
  velocity_ = s.velocity;
  contact_force_ = s.contact_force;
  indenter_center_ = s.indenter_center;
  indenter_velocity_ = s.indenter_velocity;
  indenter_contact_force_ = s.indenter_contact_force;
  contact_index_.assign(s.contact_index.begin(), s.contact_index.end());
  contact_multiplier_.assign(s.contact_multiplier.begin(), s.contact_multiplier.end());
  health_ = s.health;
  tick_ = s.tick;
}

void Checkpoint::restore(State& s) const {
  s.position = position_;
  s.velocity = velocity_;
  s.contact_force = contact_force_;
  s.indenter_center = indenter_center_;
  s.indenter_velocity = indenter_velocity_;
  s.indenter_contact_force = indenter_contact_force_;
  s.contact_index.assign(contact_index_.begin(), contact_index_.end());
  s.contact_multiplier.assign(contact_multiplier_.begin(), contact_multiplier_.end());
  s.health = health_;
  s.health.report = {};
}

}  // namespace palpate
