#pragma once
// Read-only diagnostics of a state for the stability studies (tools/stress/,
// tests/stability_test.cpp) and for per-step checks: energies and the
// deformation-gradient determinants that show inverted material. Nothing here
// is called by step(); every function works for both solid models.
#include <vector>

#include "core/model.h"
#include "core/options.h"
#include "core/state.h"
#include "core/types.h"

namespace palpate {

// Kinetic energy of the free particles and of the indenter (of mass opt.indenter_mass), J.
double kinetic_energy(const Model& model, const Options& opt, const State& state);
// Kinetic energy plus strain energy (elastic_energy of core/solid.h), J.
double total_energy(const Model& model, const Options& opt, const State& state);

// det F of the deformation gradient where the model evaluates it: per particle
// for the MLS solid (A-9, every particle, fixed ones included), at the 2x2x2
// Gauss points for the hex FEM (the smallest of an element's eight per element).
// Writes one value per particle (MLS) or per element (hex FEM) into `out`.
void jacobian_determinants(const Model& model, const Points& x, std::vector<double>& out);

struct InversionSummary {
  double min_jacobian = 1.0;  // smallest det F
  int inverted = 0;           // particles (MLS) or elements (hex FEM) with det F <= 0
  int points = 0;             // how many were checked
};
InversionSummary inversion_summary(const Model& model, const Points& x);

// The checkerboard pattern s_i = (-1)^(a+b+c) of lattice node (a, b, c), the
// pattern of nodal integration's zero-energy mode (docs/physics.md §1). Needs a
// lattice cloud (grid or graded_grid): throws std::invalid_argument otherwise.
std::vector<double> checkerboard_sign(const Model& model);
// Amplitude of the checkerboard in a displacement field u = x - X (3 x n):
// a = |sum_i s_i u_i| / (number of free particles), over the free particles, m.
double checkerboard_amplitude(const Model& model, const std::vector<double>& sign, const Points& x);

}  // namespace palpate
