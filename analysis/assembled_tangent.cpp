#include "analysis/assembled_tangent.h"

#include <algorithm>
#include <stdexcept>

#include "core/solid.h"

namespace palpate {

AssembledTangent::AssembledTangent(const Model& model, std::vector<int> free_dof, int free_count)
    : model_(model), free_dof_(std::move(free_dof)), free_count_(free_count) {
  if (model.solid != SolidKind::hex_fem || model.hex.element_count == 0)
    throw std::invalid_argument("AssembledTangent: needs a hex_fem model (its elements give the coupling)");
  const int n = model.particle_count;
  neighbours_.assign(n, {});
  for (const auto& nodes : model.hex.element_nodes)
    for (int a : nodes)
      for (int b : nodes) neighbours_[a].push_back(b);
  for (auto& list : neighbours_) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }
  // Greedy distance-2 colouring: a node's colour differs from every node within two
  // element steps (any two nodes of one colour have no common neighbour).
  colour_.assign(n, -1);
  std::vector<int> seen_at(n + 64, -1);  // colour -> last node that forbade it
  for (int i = 0; i < n; ++i) {
    for (int j : neighbours_[i])
      for (int k : neighbours_[j])
        if (colour_[k] >= 0) seen_at[colour_[k]] = i;
    int c = 0;
    while (seen_at[c] == i) ++c;
    colour_[i] = c;
    colour_count_ = std::max(colour_count_, c + 1);
  }
  dx_.setZero(3, n);
  df_.setZero(3, n);
}

void AssembledTangent::assemble(const Points& x, Workspace& work, SparseMatrix& lower) {
  const int n = model_.particle_count;
  linearize_elastic(model_, x, work);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<size_t>(free_count_) * 41);
  for (int c = 0; c < colour_count_; ++c)
    for (int d = 0; d < 3; ++d) {
      dx_.setZero();
      for (int j = 0; j < n; ++j)
        if (colour_[j] == c && free_dof_[3 * j + d] >= 0) dx_(d, j) = 1.0;
      elastic_force_differential(model_, work, dx_, df_);  // df = -K dx
      for (int i = 0; i < n; ++i)
        for (int j : neighbours_[i]) {
          if (colour_[j] != c) continue;
          const int col = free_dof_[3 * j + d];
          if (col < 0) continue;
          for (int r = 0; r < 3; ++r) {
            const int row = free_dof_[3 * i + r];
            if (row >= col) triplets.emplace_back(row, col, -df_(r, i));
          }
        }
    }
  lower.resize(free_count_, free_count_);
  lower.setFromTriplets(triplets.begin(), triplets.end());
}

}  // namespace palpate
