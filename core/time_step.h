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

// The stable step of an explicit integrator from the model's own highest frequency, for
// clouds the spacing estimate misjudges (a refined mesh's close pairs: docs/stability.md,
// "The spectral estimate"): omega_max^2 the largest eigenvalue of M^-1 K, K the MLS tangent
// at the rest configuration (hourglass and volume terms included) on the free particles, by
// Lanczos (full reorthogonalisation; at most 60 steps, ended from 20 steps on once the largest
// Ritz value's residual bound is within 1e-6 of it) plus that residual, so it does not fall
// short of omega_max; dt = 2 / omega_max for symplectic Euler (2.785 for RK4). Symplectic
// Euler and RK4 on the MLS model only; 0 otherwise. Costs 20-60 tangent products (about
// 10 ms on the refined palpation block: 30 steps there).
double spectral_time_step(const Model& model, IntegratorType integrator);
// The fraction of spectral_time_step that check_options accepts. Contact and the law under
// load lower the limit a little: on palpation_block_follow pressed with 0.262 N the measured
// largest stable step (palpate-stable-dt) is 0.6 % below the unloaded spectral one at
// (35, 35) mm (1.234 against 1.242 ms), and the free body's limit lies between 0.98 and 1.02
// of it (tests/spectral_time_step_test.cpp): 0.85 keeps a margin of about 14 %. Not so on
// every cloud: on a 10^3 lattice under the Hertz cube's 327.6 N and 1 kg tool the loaded limit
// is 0.63 of 2 / omega_max (docs/stability.md, "The envelope"), so build_model uses it for
// refined meshes (body.distribution.refine) only, where it was measured.
inline constexpr double kSpectralSafety = 0.85;

// Checks options against the model before they are used: throws SceneError (source:
// the model's scene, field /integrator/dt) when opt.integrator.dt > stable_time_step,
// naming the envelope, unless opt.integrator.allow_unstable_dt, or the model carries a
// spectral_time_step and dt <= kSpectralSafety times it. build_model runs it on the scene's
// options; a caller that changes the options runs it again.
void check_options(const Model& model, const Options& opt);

}  // namespace palpate
