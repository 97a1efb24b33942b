#pragma once
// One simulation tick, in stage order: free motion by the scene's integrator
// (elastic forces, damping, gravity, commanded indenter force) -> contact solve
// and correction -> time bookkeeping -> finiteness check.
#include "core/model.h"
#include "core/state.h"

namespace palpate {

// Advances the state by the scene's dt. The caller sets state.force_command
// (the real-time input) before the call.
StepStatus step(const Model& model, State& state);

const char* to_string(StepStatus);

}  // namespace palpate
