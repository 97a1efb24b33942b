#pragma once
// The tangent stiffness K(x) = -df/dx of a hexahedral model as a sparse matrix over its
// free degrees of freedom, recovered from the matrix-free differential of core/solid.h
// (linearize_elastic, elastic_force_differential) by colouring (Curtis, Powell and Reid):
// nodes that share no element with a common node get one colour; a probe dx = the unit
// vector of direction d at every node of colour c gives, at node i, minus the columns
// (j, d) of the one node j of colour c that shares an element with i. A lattice needs 27
// colours, so K costs 81 differentials, whatever the formulation (linear, corotational,
// neo-Hookean (5.6)): the assembled matrix is exactly the operator the implicit
// integrator applies, with no second implementation of any element tangent to keep in step.
#include <Eigen/SparseCore>
#include <vector>

#include "core/model.h"
#include "core/state.h"

namespace palpate {

class AssembledTangent {
 public:
  using SparseMatrix = Eigen::SparseMatrix<double>;

  // The colouring of the model's elements (throws std::invalid_argument for a model
  // without elements: the meshless solid's coupling is its neighbour lists, not cells).
  // free_dof: 3n, the index of each DOF among the free ones, -1 for fixed.
  AssembledTangent(const Model& model, std::vector<int> free_dof, int free_count);

  // The lower triangle of K(x) over the free DOFs; `work` caches the linearisation.
  void assemble(const Points& x, Workspace& work, SparseMatrix& lower);

  int colour_count() const { return colour_count_; }

 private:
  const Model& model_;
  std::vector<int> free_dof_;
  int free_count_ = 0;
  std::vector<int> colour_;                 // per node
  int colour_count_ = 0;
  std::vector<std::vector<int>> neighbours_;  // per node: the nodes sharing an element with it (itself included)
  Points dx_, df_;
};

}  // namespace palpate
