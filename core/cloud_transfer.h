#pragma once
// Carrying a deformed state from one cloud of a body to another cloud of the same body
// (a refocus: core/mesh_refinement.h). The displacement and velocity fields of the old
// cloud are interpolated linearly over its tetrahedra at the new particles' reference
// positions (docs/physics.md (7.2)):
//
//   u(X) = sum_a lambda_a(X) u_a,   v(X) = sum_a lambda_a(X) v_a                  (7.2)
//
// lambda_a the barycentric coordinates of X in the old tetrahedron that holds it. A new
// particle at an old particle's reference position takes its values exactly (the base's
// vertices and the midpoints both refinements made). The weights depend only on the two
// reference configurations, so they are made once per refocus (off the real-time thread);
// applying them (transfer_state) is a sparse product of at most four terms per particle.
#include <array>
#include <vector>

#include "core/model.h"
#include "core/state.h"
#include "core/types.h"

namespace palpate {

struct CloudTransfer {
  int new_count = 0;
  std::vector<int> offset;     // new_count + 1: the terms of new particle i are offset[i] ... offset[i+1]-1
  std::vector<int> source;     // old particle of each term
  std::vector<double> weight;  // lambda of each term (a row sums to 1)
  // The other way, for forces: each old particle located in the new cloud's tetrahedra.
  std::vector<int> back_offset;     // old count + 1
  std::vector<int> back_source;     // new particle of each term
  std::vector<double> back_weight;  // its barycentric coordinate
  mutable std::vector<int> new_slot;  // new count, -1: transfer_state's scratch (its contact slots)
  int exact = 0;               // new particles that coincide with an old one
  double worst_outside = 0.0;  // the most negative barycentric coordinate accepted (a face's round-off, a facet's sag)
};

// The weights (7.2) from the old cloud (reference positions and tetrahedra) to the new one,
// and back. A position just outside the other cloud (a curved body's new surface vertex,
// outside the other refinement's facets by their sag: a barycentric coordinate down to
// -0.05) is extrapolated from the nearest tetrahedron; one further outside every
// tetrahedron is a std::invalid_argument: the two clouds are not of the same body.
CloudTransfer make_cloud_transfer(const Points& old_rest, const std::vector<std::array<int, 4>>& old_tetrahedra,
                                  const Points& new_rest, const std::vector<std::array<int, 4>>& new_tetrahedra);

// `to_state` (a state of the new model, e.g. make_state's) takes the deformation of `from`:
// positions X_i + u(X_i), velocities v(X_i) by (7.2); the tool (centre, velocity, command,
// target), the clock, the tick and the health bookkeeping are copied. The contact set is
// carried as point forces: the force on an old particle, applied at its reference position,
// goes to the vertices of the new tetrahedron there by their barycentric coordinates (the
// same virtual work for any linear field), so the total force on the body and the tool's
// contact force are kept; particles with a share become the new contact set, their
// multipliers the normal components (a share on a fixed particle is dropped). Allocates
// nothing: a swap at a tick boundary costs one pass over the terms.
void transfer_state(const CloudTransfer& transfer, const Model& from_model, const CarriedState& from,
                    const Model& to_model, State& to_state);

}  // namespace palpate
