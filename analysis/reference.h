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

#include "core/model.h"
#include "core/reference_file.h"
#include "core/scene.h"
#include "core/state.h"

namespace palpate {


// Refuses (std::invalid_argument, "FIELD: ...") a site off the top face, or closer to a
// side wall than the indenter radius R, (4.2) (the footprint within which the touch height is
// taken, docs/physics.md (2.5), must lie on the face). `field` names where the site came
// from (--site, or /indenter/position). The centre of the top face is always accepted (a
// sphere wider than the face presses it, as the R = 5 m strain study does).
void check_site(const Scene& scene, const std::string& field);

// Places the indenter over (x, y), at rest just touching the undeformed body (the
// highest point of the scene's own cloud under the sphere, as build_model places a
// centred indenter), after check_site. A graded lattice without its own focus is
// graded toward the site (core/node_cloud.h, graded_focus).
void place_indenter_at_site(Scene& scene, double x, double y, const std::string& field = "--site");

// The height of the centre of a sphere of radius R over (x, y) when it first touches one
// of the points X (3 x n); -inf when none lies within R horizontally.
double first_contact_height(const Points& X, double R, double x, double y);

// The touch height z_touch of (2.5) over (x, y): the height of the sphere's centre when it
// first touches the reference configuration's surface triangles (2.16), as build_model
// measures model.touch_height; for a cloud without a surface (4.1), R + the height of the
// highest particle within horizontal distance R. Computed from the body, so a face that is
// not flat or a cloud without a node under the site is measured as is.
double touch_height_at(const Model& model, double x, double y);

// The indentation under the tool's actual (x, y) (docs/physics.md (2.5)):
// d = touch_height_at(c_x, c_y) - c_z. Equals core's indentation() while the tool is at
// its start's (x, y) (a vertical guide); a free tool (the sliding study) needs this one.
double indentation_at_tool(const Model& model, const State& state);

struct ReferenceOptions {
  std::vector<int> levels{17, 25, 33, 41};  // nodes per edge, coarse to fine (at least 3)
  int base_per_edge = 21;                   // the lattice on which first_spacing is given
  // m, at base_per_edge (docs/physics.md §6, "Grading toward the contact fixes it cheaply");
  // 0: 0.05 R, scaled with the indenter radius (0.025 m for the default R = 0.5 m)
  double base_first_spacing = 0.0;
};



// Computes the reference at `forces` for the scene's site (indenter_site): every level's
// lattice is graded toward the site, with a node on it, and its contact candidates are
// the top-face nodes under the sphere there. `progress(message)` (optional) reports each level.
Reference finite_cube_reference(const Scene& scene, const std::vector<double>& forces,
                                const ReferenceOptions& options = {},
                                const std::function<void(const std::string&)>& progress = {});

// The large-strain reference (docs/physics.md §5, "The large-strain reference"): the scene's
// block as neo-Hookean bricks (5.4)-(5.6) on the graded lattices of finite_cube_reference
// (`levels` nodes per edge; the site must be the centre of the top face), the tool held at each
// of `depths` (m, increasing) below first touch (held_tool_static.h), and Richardson on the
// force at each depth, as on the indentation in finite_cube_reference. The result has
// indentation = depths and forces = F*(d); its uncertainty is in depth, the force's
// converted with the local slope of the extrapolated curve. Key: large_strain_reference_key.
//
// With core_half_width w > 0 the family is another (docs/physics.md §5): a quarter of the block
// (x >= the site's x, y >= the site's y, mirror conditions u_x = 0 and u_y = 0 on the cut
// planes, the force times 4), whose three axes each run from the site with `core_share` of
// their intervals uniform over [0, w] (spacing h = w / round(core_share n)) and the rest graded
// geometrically from h to the box face (core_graded_axis). Level N has N nodes per axis of the
// quarter (n = N - 1 intervals), so h is proportional to 1 / n and the contact patch, when
// w exceeds its radius, is sampled uniformly at every level. Requires a homogeneous body with
// the fixed faces symmetric about the site (x_min with x_max, y_min with y_max), no fixed regions.
struct LargeStrainLattice {
  double core_half_width = 0.0;  // m; 0: the graded family of finite_cube_reference on the whole block
  double core_share = 0.6;       // the share of each axis's intervals inside the core
};
Reference large_strain_reference(const Scene& scene, const std::vector<double>& depths,
                                 const std::vector<int>& levels = {17, 21, 25, 29},
                                 const std::function<void(const std::string&)>& progress = {},
                                 const LargeStrainLattice& lattice = {});

// Coordinates of intervals + 1 nodes from `focus` to `end` (either side of it; the first is
// focus, the last exactly end): core_intervals equal intervals of core_length / core_intervals,
// then intervals - core_intervals growing geometrically from that spacing (the first of
// them equal to it) to end. Throws std::invalid_argument when the core does not fit (it is not
// shorter than |end - focus|, there is no interval outside it, or the outer intervals would
// have to shrink).
std::vector<double> core_graded_axis(double focus, double end, int intervals, int core_intervals, double core_length);


// Extrapolates d(h) = d* + C h^p from three (h, d) pairs, h decreasing. Returns
// false (and d* = the finest value, p = 0) when the differences do not converge
// monotonically.
bool richardson(const double h[3], const double d[3], double& extrapolated, double& order);


// Fills ref.indentation, uncertainty and order from its levels' indentation: Richardson over
// the three finest levels in h (1 / (per_edge - 1), or first_spacing when per_edge is 0) where
// they converge monotonically at an order in [0.5, 4] and, with four or more levels, the next
// coarser triple agrees on the order within half of it; elsewhere the finest level, with the
// spread of the three finest as its uncertainty and order 0.
void extrapolate_indentation(Reference& ref);

// JSON text of a reference (read back by reference_from_json, core/reference_file.h).
std::string reference_to_json(const Reference& reference);

}  // namespace palpate
