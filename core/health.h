#pragma once
// Per-step health checks (Options::health, scene field "health"): the last stage of step(). Cheap
// by construction — one pass over the velocities, the contact candidates, and a
// rotating window of deformation gradients — so that a numerical blow-up is caught
// on the tick it happens, with its reason, before the state leaves the core.
//
// Checks, in order (the first failure is reported):
//  - non_finite:        a NaN or Inf in positions, velocities, the indenter or the contact force;
//  - energy_jump:       kinetic energy (body + indenter) above energy_factor x the energy budget
//                       (initial energy + work of the command and of gravity, its running maximum;
//                       the total energy can only be below it, with damping less) plus a floor
//                       of 1/2 M_body (c_p / 400)^2 (the free body at the particle speed of a
//                       p-wave of strain 1/400: it scales with the scene);
//  - indenter_speed:    |v_indenter| above max_indenter_speed (default: one minimum particle
//                       spacing per step, beyond which contact can tunnel) while the tool is
//                       within two steps' travel of a particle (a tool in free flight, lifted
//                       off the body, is not judged: the workspace box keeps it in reach);
//  - penetration:       a contact candidate deeper inside the sphere than max_penetration (default:
//                       the contact tolerance + 5 % of the minimum spacing) after the contact solve;
//  - inverted_particle: det F_i <= 0 at an MLS particle (checked for n / inversion_sweep_ticks
//                       particles per step, all of them every inversion_sweep_ticks steps). Only a
//                       fault without the volume term (k_v = 0): with k_v > 0 the solid is meant to
//                       push the particle back, and State::health.inverted counts them instead.
// The hex FEM has no inversion check (its linear and corotational forms have no det F).
#include <cstdint>
#include <string>

#include "core/model.h"
#include "core/options.h"
#include "core/state.h"

namespace palpate {

// Runs the checks after a step; `status` is what the step's stages reported.
// Returns the first failure (or `status`), and records it in state.health.report.
StepStatus check_health(const Model& model, const Options& opt, State& state, StepStatus status);

// Restarts the energy budget from the state as it is (initial energy = kinetic +
// strain energy: one energy evaluation; the gravity potential under opt.gravity).
// make_state() calls it; so must whoever sets a state by hand (a restored Checkpoint
// carries its own budget).
void reset_health(const Model& model, const Options& opt, State& state);

// The limits in force: opt.health's, or derived from the model and opt (dt, contact
// tolerance) where opt.health says 0. Cheap: check_health derives them every step,
// so changed options take effect at once.
HealthLimits health_limits(const Model& model, const Options& opt);

// "energy jump at tick 1234: kinetic energy 5.2 J above the limit 3.1 J (10 x budget + floor)".
std::string describe(const HealthReport& report);

}  // namespace palpate
