#pragma once
// Consistent nodal integration of the MLS solid (docs/physics.md §1, "Consistent integration"; measured in §6).
//
// Nodal integration evaluates the strain energy at the particles with the MLS
// gradient weights g_ij (d_j of particle i for a neighbour j, A-8; g_ii = d_i =
// -sum_j d_j). A uniform stress then leaves node j the force -sigma sum_i v_i g_ij,
// which vanishes only if the integration constraint
//     sum_i v_i g_ij = 0   at every interior node j                  (IC)
// holds: the discrete divergence theorem. On a regular lattice it holds by
// symmetry; on jittered, graded-and-stretched or tetrahedralisation clouds it does
// not, and the solid fails the patch test and comes out too soft.
//
// The correction (variationally consistent integration in the spirit of Chen,
// Hillman and Ruter 2013): g~_ij = g_ij + delta_ij with the least-norm delta that
//   (a) keeps the gradient exact for linear fields: sum_j delta_ij X_ij^T = 0 at every i,
//   (b) keeps g~_ii = -sum_j g~_ij (constant fields give zero gradient), and
//   (c) imposes (IC) at every interior node.
// delta = B^T (B B^T)^-1 b, with B the constraint matrix over the neighbour entries
// (the same for the three components): one sparse factorisation at set-up, three
// solves. Forces stay the exact gradient of the (corrected) discrete energy, since
// the force loop uses the corrected weights everywhere; nothing changes per step.
#include <cstdint>
#include <vector>

#include "core/model.h"

namespace palpate {

struct IntegrationCorrection {
  int interior_nodes = 0;          // nodes where (IC) is imposed
  double residual_before = 0.0;    // max_j |sum_i v_i g_ij| / typical |v_i g_ij|, interior j
  double residual_after = 0.0;     // the same with the corrected weights
  double relative_change = 0.0;    // ||delta|| / ||g|| over all neighbour entries
};

// max over interior nodes j of |sum_i v_i g_ij|, relative to the mean |v_i g_ij|.
double integration_residual(const Model& model, const std::vector<uint8_t>& interior);

// Corrects model.gradient_weight in place (before the blocked force layout is built).
IntegrationCorrection make_integration_consistent(Model& model, const std::vector<uint8_t>& interior);

}  // namespace palpate
