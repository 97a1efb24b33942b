#pragma once
// The converged reference of the finite block (docs/physics.md §5, "The finite-block reference"): the linear
// hexahedral FEM of the scene's block, material, fixed faces and sphere, solved
// quasi-statically and exactly (static_contact.h) on a family of lattices graded
// toward the contact point and refined uniformly in the graded coordinate, with
// Richardson extrapolation of the indentation at each force.
//
// Level k has N_k nodes per edge; the first spacing scales so that the vertical
// axis keeps one geometric mapping (s_k = L (r_k - 1) / (r_k^n_k - 1), r_k^n_k fixed):
// the lattices are samples of one smooth map, h_k = 1 / (N_k - 1), and
// d_k(F) = d*(F) + C h_k^p. From the three finest levels p and d* follow
// (observed order, solved numerically for unequal ratios); the uncertainty is the
// larger of 1.25 |d* - d_finest| (Roache's grid convergence index) and the change
// of d* when the next coarser triple is used. Contact makes the sequence oscillate
// (nodes enter the contact ring by ring): where the three finest levels are not
// monotone, the observed order is outside [0.5, 4] or differs by more than half from
// that of the next coarser triple, d* is the finest level and
// the uncertainty the spread of the three finest.
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/scene.h"

namespace palpate {

struct ReferenceOptions {
  std::vector<int> levels{17, 25, 33, 41};  // nodes per edge, coarse to fine (at least 3)
  int base_per_edge = 21;                   // the lattice on which first_spacing is given
  // m, at base_per_edge (docs/physics.md §6, "Grading toward the contact fixes it cheaply");
  // 0: 0.05 R, scaled with the indenter radius (0.025 m for the default R = 0.5 m)
  double base_first_spacing = 0.0;
};

struct ReferenceLevel {
  int per_edge = 0;
  int nodes = 0;
  double first_spacing = 0.0;      // m
  std::vector<double> indentation; // per force, m
  double seconds = 0.0;            // wall time of the level (assembly, factorisation, sweep)
};

struct Reference {
  std::vector<double> forces;        // N
  std::vector<ReferenceLevel> levels;
  std::vector<double> indentation;   // d*(F), extrapolated, m
  std::vector<double> uncertainty;   // m
  std::vector<double> order;         // observed convergence order p per force
  std::string key;                   // what the reference depends on (reference_key)
};

// The scene fields the reference depends on, as one line (box, material, fixed faces,
// indenter radius and site); two scenes with the same key share a reference.
std::string reference_key(const Scene& scene);

// Computes the reference at `forces`. `progress(message)` (optional) reports each level.
Reference finite_cube_reference(const Scene& scene, const std::vector<double>& forces,
                                const ReferenceOptions& options = {},
                                const std::function<void(const std::string&)>& progress = {});

// d*(F) at an arbitrary force in the reference's range: d^(3/2) interpolated linearly
// in F (Hertz: F ~ d^(3/2)), exact at the reference forces. NaN outside the range.
double reference_indentation(const Reference& reference, double force);

// Extrapolates d(h) = d* + C h^p from three (h, d) pairs, h decreasing. Returns
// false (and d* = the finest value, p = 0) when the differences do not converge
// monotonically.
bool richardson(const double h[3], const double d[3], double& extrapolated, double& order);

// A reference file written by palpate-reference --out (throws std::runtime_error).
Reference load_reference(const std::filesystem::path& file);

// The stored reference in `folder` (*.json written by palpate-reference --out) whose
// key matches the scene's; nullopt when there is none.
std::optional<Reference> find_reference(const Scene& scene, const std::filesystem::path& folder);

// JSON text of a reference, and back (throws std::runtime_error naming the problem).
std::string reference_to_json(const Reference& reference);
Reference reference_from_json(const std::string& text);

}  // namespace palpate
