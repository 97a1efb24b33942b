#pragma once
// The large-strain static contact of a hexahedral body with a sphere held at a given
// centre (docs/physics.md §5, "The large-strain reference"): the equilibrium of the
// nonlinear elastic forces (any hex formulation; the neo-Hookean bricks (5.4)-(5.6) are
// what it is for) with frictionless contact in the deformed configuration,
//   f_int(x) + sum_i p_i n_i = 0,   g_i = |x_i - c| - R >= 0,  p_i >= 0,  p_i g_i = 0,   (5.7)
// n_i = (x_i - c) / |x_i - c|, solved by the augmented Lagrangian (5.8): Newton on
//   Pi(x) + sum_i (max(0, lambda_i - k g_i)^2 - lambda_i^2) / (2 k)
// with the tangent assembled exactly (analysis/assembled_tangent.h) plus the contact term's
// Hessian k n_i n_i^T - p_i (I - n_i n_i^T) / |x_i - c| on the nodes in contact, factorised
// by CHOLMOD, an energy line search, and the update
// lambda_i <- max(0, lambda_i - k g_i) until the penetration is below tolerance.
// The tool is displacement-controlled, so the path through large depths has no limit
// point; the depth is reached in increments from the previous solution, each started from
// the secant extrapolation of the last two solutions (positions and multipliers).
#include <memory>
#include <string>
#include <vector>

#include "core/model.h"
#include "core/types.h"

namespace palpate {

struct HeldToolOptions {
  double force_tolerance = 0.0;   // N, the largest net force left on a free node; 0 = 1e-9 E R^2
  double gap_tolerance = 0.0;     // m, the largest penetration left; 0 = 1e-7 R
  double max_increment = 0.0;     // m, the largest step of the tool between solves; 0 = 0.05 R
  int max_newton = 60;            // Newton iterations per augmentation
  int max_augmentations = 40;
  // Mirror planes through the tool's axis: for each axis a listed (0 = x, 1 = y), the nodes
  // whose rest coordinate a equals the tool start's keep u_a = 0 (a half or quarter of a
  // body symmetric about those planes; tool_force is then the modelled part's).
  std::vector<int> mirror_axes;
};

struct HeldToolSolution {
  bool converged = false;
  Vec3 tool_force{0, 0, 0};       // N, the force of the (modelled part of the) body on the tool (z up when pressed)
  double residual = 0.0;          // N, largest net force on a free node
  double max_penetration = 0.0;   // m
  int active_count = 0;           // nodes pressed by the sphere
  int newton_iterations = 0;      // in all, over the increments and augmentations
  std::string message;            // why it did not converge
};

class HeldToolStatics {
 public:
  // Throws std::invalid_argument unless the model is a hex_fem model.
  explicit HeldToolStatics(const Model& model, const HeldToolOptions& options = {});
  ~HeldToolStatics();
  HeldToolStatics(const HeldToolStatics&) = delete;
  HeldToolStatics& operator=(const HeldToolStatics&) = delete;

  // The equilibrium with the sphere's centre at `centre`, reached from the last solution
  // (the rest state at first) in straight increments of at most max_increment.
  HeldToolSolution solve(const Vec3& centre);

  const Points& positions() const;     // x of the last solution, 3 x n
  const std::vector<double>& contact_pressure() const;  // p_i per node, N (0 off contact)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpate
