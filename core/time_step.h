#pragma once
// The stable time step of the integrators (docs/physics.md §1, "Time step"):
// dt_max = c * dx_min / c_p, with dx_min the smallest particle spacing (FEM: element
// edge) and c_p = sqrt((lambda + 2 mu + k_v) / rho) the p-wave speed (the volume
// term stiffens the dilatational wave). c was measured by bisection
// (palpate-stable-dt, palpate-stress; docs/stability.md) for each model and
// integrator on the uniform and the graded default clouds (other clouds get the
// smaller of the two), so a scene inside it is inside the measured envelope.
// Implicit Euler has a limit too (time_step.cpp says why).
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"

namespace palpate {

// c of the envelope.
double stability_constant(SolidKind solid, IntegratorType integrator, DistributionType distribution);

// dt_max of the model with `integrator`, s.
double stable_time_step(const Model& model, IntegratorType integrator);

// Checks options against the model before they are used: throws SceneError (source:
// the model's scene, field /integrator/dt) when opt.integrator.dt > stable_time_step,
// naming the envelope, unless opt.integrator.allow_unstable_dt. build_model runs it on
// the scene's options; a caller that changes the options runs it again.
void check_options(const Model& model, const Options& opt);

}  // namespace palpate
