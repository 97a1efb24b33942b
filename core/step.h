#pragma once
// One simulation tick, in stage order: free motion by the options' integrator
// (elastic forces, damping, gravity, commanded indenter force) -> contact solve
// and correction -> time bookkeeping -> health checks (or finiteness alone).
#include "core/model.h"
#include "core/options.h"
#include "core/state.h"

namespace palpate {

// Advances the state by opt.integrator.dt. The caller sets state.force_command
// (the real-time input) before the call; opt may differ from step to step.
StepStatus step(const Model& model, const Options& opt, State& state);

// The end of every step, after the contact solve returned `status`: the time bookkeeping,
// then the health checks (or, with them off, finiteness alone). For steppers built from
// other stages (analysis/exact_coupled_contact.h).
StepStatus end_step(const Model& model, const Options& opt, State& state, StepStatus status);

const char* to_string(StepStatus);

}  // namespace palpate
