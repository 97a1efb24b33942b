#pragma once
// Implicit Euler's contact solve with the Delassus operator formed exactly, as core did
// before issue #17: W = dt^2 J A^-1 J^T + the tool's part (docs/physics.md (2.4)), one CG
// solve of the step operator A (1.12) per contact candidate (to cg_tolerance), then the two
// LCPs of core/contact.h on it by principal pivoting. A reference for tests and studies
// (m CG solves and 3 n m doubles of responses per step): core's solve_contact reaches the
// same solution through the compliance cache and the splitting of (2.17), (2.18).
#include "core/model.h"
#include "core/options.h"
#include "core/state.h"

namespace palpate {

// solve_contact(model, opt, state, &A) with W formed exactly (A: the ImplicitEulerOperator
// of the step). Touches neither the compliance cache nor core's contact counters beyond
// contact_iterations, contact_max_penetration and contact_candidate.
StepStatus solve_contact_exact_delassus(const Model& model, const Options& opt, State& state);

// step() of implicit Euler with the contact solve above (the free motion, the clock, the
// health checks as step() does them).
StepStatus step_implicit_euler_exact(const Model& model, const Options& opt, State& state);

}  // namespace palpate
