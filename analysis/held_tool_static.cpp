#include "analysis/held_tool_static.h"

#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <spdlog/spdlog.h>
#include <stdexcept>

#include "analysis/assembled_tangent.h"
#include "core/solid.h"
#include "core/state.h"

namespace palpate {

namespace {

std::vector<int> free_dofs_of(const Model& model, int& count) {
  std::vector<int> free_dof(3 * static_cast<size_t>(model.particle_count), -1);
  count = 0;
  for (int i = 0; i < model.particle_count; ++i)
    if (!model.fixed[i])
      for (int c = 0; c < 3; ++c) free_dof[3 * i + c] = count++;
  return free_dof;
}

}  // namespace

struct HeldToolStatics::Impl {
  using SparseMatrix = Eigen::SparseMatrix<double>;
  const Model& model;
  HeldToolOptions opt;
  int free_count = 0;
  std::vector<int> free_dof;
  AssembledTangent tangent;
  Workspace work;
  Points x, trial, f;                 // positions, a trial step, forces (3 x n)
  Vec3 centre;                        // the sphere's centre of the last solution
  double penalty = 0.0;               // k of (5.8), N/m
  std::vector<double> lambda, pressure;  // per node: multiplier estimate, p_i at x
  Eigen::VectorXd residual, step;
  Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower> cholesky;
  bool pattern_analysed = false;

  Impl(const Model& m, const HeldToolOptions& o)
      : model(m), opt(o), free_dof(free_dofs_of(m, free_count)), tangent(m, free_dof, free_count) {
    const double R = m.indenter_radius;
    const double E = m.lame_mu * (3 * m.lame_lambda + 2 * m.lame_mu) / (m.lame_lambda + m.lame_mu);
    if (opt.force_tolerance <= 0) opt.force_tolerance = 1e-9 * E * R * R;
    if (opt.gap_tolerance <= 0) opt.gap_tolerance = 1e-7 * R;
    if (opt.max_increment <= 0) opt.max_increment = 0.05 * R;
    x = m.rest_position;
    trial = x;
    f.setZero(3, m.particle_count);
    centre = m.indenter_start;
    lambda.assign(m.particle_count, 0.0);
    pressure.assign(m.particle_count, 0.0);
    residual.setZero(free_count);
    step.setZero(free_count);
    cholesky.cholmod().print = 0;  // an indefinite tangent is handled below, not printed
    // k of (5.8): 100 times the stiffest node's own stiffness at rest, so each augmentation
    // gains about a factor 100 on the penetration while the factorisation stays accurate.
    SparseMatrix K;
    tangent.assemble(x, work, K);
    double diagonal = 0;
    for (int k = 0; k < K.outerSize(); ++k) diagonal = std::max(diagonal, K.coeff(k, k));
    penalty = 100 * diagonal;
  }

  // The augmented contact term of (5.8) at positions y: its energy, and p_i.
  double contact_energy(const Points& y, const Vec3& c, std::vector<double>* p) const {
    const double R = model.indenter_radius;
    double energy = 0;
    for (int i = 0; i < model.particle_count; ++i) {
      if (model.fixed[i]) continue;
      const double g = (y.col(i) - c).norm() - R;
      const double pi = std::max(0.0, lambda[i] - penalty * g);
      energy += (pi * pi - lambda[i] * lambda[i]) / (2 * penalty);
      if (p) (*p)[i] = pi;
    }
    return energy;
  }

  double merit(const Points& y, const Vec3& c) const {
    const double e = elastic_energy(model, y);
    return std::isfinite(e) ? e + contact_energy(y, c, nullptr) : INFINITY;
  }

  // r = f_int + sum p_i n_i over the free DOFs (5.7); returns the largest nodal |r|.
  double compute_residual(const Vec3& c) {
    elastic_forces(model, x, f);
    contact_energy(x, c, &pressure);
    double worst = 0;
    for (int i = 0; i < model.particle_count; ++i) {
      if (model.fixed[i]) continue;
      Vec3 r = f.col(i);
      if (pressure[i] > 0) r += pressure[i] * (x.col(i) - c).normalized();
      for (int a = 0; a < 3; ++a) residual[free_dof[3 * i + a]] = r[a];
      worst = std::max(worst, r.norm());
    }
    return worst;
  }

  bool newton_step(const Vec3& c, std::string& message) {
    SparseMatrix K;
    tangent.assemble(x, work, K);
    // + k n n^T on the pressed nodes (lower triangle; the node's own block is in K's pattern).
    std::vector<Eigen::Triplet<double>> extra;
    for (int i = 0; i < model.particle_count; ++i) {
      if (model.fixed[i] || pressure[i] <= 0) continue;
      const Vec3 n = (x.col(i) - c).normalized();
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b <= a; ++b)
          extra.emplace_back(free_dof[3 * i + a], free_dof[3 * i + b], penalty * n[a] * n[b]);
    }
    SparseMatrix P(free_count, free_count);
    P.setFromTriplets(extra.begin(), extra.end());
    K += P;
    if (!pattern_analysed) {
      cholesky.analyzePattern(K);
      pattern_analysed = true;
    }
    cholesky.factorize(K);
    // Far from equilibrium the neo-Hookean tangent of strongly compressed bricks may be
    // indefinite: then the step is taken with K + mu D (D the diagonal of K, mu raised
    // tenfold until the factorisation succeeds), a descent direction the line search can use.
    double shift = 0.0;
    if (cholesky.info() != Eigen::Success) {
      const Eigen::VectorXd diagonal = K.diagonal();
      for (shift = 1e-6; shift <= 1e3 && cholesky.info() != Eigen::Success; shift *= 10) {
        SparseMatrix shifted = K;
        for (int k = 0; k < free_count; ++k) shifted.coeffRef(k, k) += shift * diagonal[k];
        cholesky.factorize(shifted);
      }
      if (cholesky.info() != Eigen::Success) {
        message = "the tangent stayed indefinite under a shift of 1000 times its diagonal (an inverted element?)";
        return false;
      }
      spdlog::debug("held tool: indefinite tangent, shifted by {:.1e} of its diagonal", shift / 10);
    }
    step = cholesky.solve(residual);
    // Energy line search: Armijo on the merit (5.8); near convergence, where the energy
    // changes at round-off, a step that lowers the residual is taken as it is.
    const double m0 = merit(x, c), slope = -residual.dot(step);
    double alpha = 1.0;
    for (int tries = 0; tries < 30; ++tries, alpha *= 0.5) {
      trial = x;
      for (int i = 0; i < model.particle_count; ++i)
        if (!model.fixed[i])
          for (int a = 0; a < 3; ++a) trial(a, i) += alpha * step[free_dof[3 * i + a]];
      const double m1 = merit(trial, c);
      if (m1 <= m0 + 1e-4 * alpha * slope || (std::isfinite(m1) && std::abs(m1 - m0) <= 1e-12 * std::abs(m0)))
        break;
    }
    x.swap(trial);
    return true;
  }

  void solve_at(const Vec3& c, HeldToolSolution& sol) {
    for (int aug = 0; aug < opt.max_augmentations; ++aug) {
      bool inner = false;
      for (int it = 0; it <= opt.max_newton; ++it) {
        sol.residual = compute_residual(c);
        if (sol.residual <= opt.force_tolerance) {
          inner = true;
          break;
        }
        if (it == opt.max_newton) break;
        ++sol.newton_iterations;
        if (!newton_step(c, sol.message)) return;
      }
      if (!inner) {
        sol.message = "Newton did not reach the force tolerance in " + std::to_string(opt.max_newton) +
                      " iterations (residual " + std::to_string(sol.residual) + " N)";
        return;
      }
      double penetration = 0;
      for (int i = 0; i < model.particle_count; ++i)
        if (!model.fixed[i])
          penetration = std::max(penetration, model.indenter_radius - (x.col(i) - c).norm());
      sol.max_penetration = penetration;
      if (penetration <= opt.gap_tolerance) {
        sol.converged = true;
        return;
      }
      lambda = pressure;  // (5.8): the multipliers of this solution
    }
    sol.message = "the penetration stayed above " + std::to_string(opt.gap_tolerance) + " m after " +
                  std::to_string(opt.max_augmentations) + " augmentations";
    return;
  }
};

HeldToolStatics::HeldToolStatics(const Model& model, const HeldToolOptions& options)
    : impl_(std::make_unique<Impl>(model, options)) {}
HeldToolStatics::~HeldToolStatics() = default;

HeldToolSolution HeldToolStatics::solve(const Vec3& target) {
  Impl& s = *impl_;
  HeldToolSolution sol;
  const Vec3 start = s.centre;
  const int increments = std::max(1, static_cast<int>(std::ceil((target - start).norm() / s.opt.max_increment)));
  for (int k = 1; k <= increments; ++k) {
    const Vec3 c = start + (target - start) * (static_cast<double>(k) / increments);
    sol.converged = false;
    s.solve_at(c, sol);
    if (!sol.converged) {
      sol.message = "at the increment " + std::to_string(k) + " of " + std::to_string(increments) + ": " + sol.message;
      return sol;
    }
    s.centre = c;
    spdlog::debug("held tool: increment {}/{} centre z {:.6g} m, {} Newton iterations so far", k, increments, c[2],
                  sol.newton_iterations);
  }
  sol.tool_force.setZero();
  sol.active_count = 0;
  for (int i = 0; i < s.model.particle_count; ++i)
    if (s.pressure[i] > 0) {
      sol.tool_force -= s.pressure[i] * (s.x.col(i) - s.centre).normalized();
      ++sol.active_count;
    }
  return sol;
}

const Points& HeldToolStatics::positions() const { return impl_->x; }
const std::vector<double>& HeldToolStatics::contact_pressure() const { return impl_->pressure; }

}  // namespace palpate
