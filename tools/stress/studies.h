#pragma once
// The five studies of palpate-stress (docs/stability.md), one file each. Every study
// adds its protocol to `meta` (the output's "definitions") and returns its result.
#include "tools/stress/harness.h"

namespace palpate::stress {

// envelope.cpp: the largest stable dt by bisection (analysis/stability.h) per model,
// integrator, cloud and damping, against dt = c dx_min / c_p. One row per case.
json envelope_study(const StressOptions& stress, json& meta);

// large_force.cpp: forces far beyond the Hertz sweep, sudden steps, a reversal. One row
// per model and force.
json large_force_study(const StressOptions& stress, json& meta);

// inversion.cpp: compression to inversion, release with and without k_v, the stable dt
// with each k_v. An object with the rows and the k_v that recover and stay stable.
json inversion_study(const StressOptions& stress, json& meta);

// zero_energy.cpp: checkerboard and velocity noise with and without hourglass control.
// One row per dynamics run; also appends the time series of the checkerboard amplitude
// to `series` and the energy and force ratios of the checkerboard to `ratios`.
json zero_energy_study(const StressOptions& stress, json& meta, json& series, json& ratios);

// long_run.cpp: 10^6 steps (--long-steps) under a periodic force command, then the rest
// state. Appends the per-period samples to `per_period`.
json long_run_study(const StressOptions& stress, json& meta, json& per_period);

}  // namespace palpate::stress
