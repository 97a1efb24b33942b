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

std::vector<int> free_dofs_of(const Model& model, const std::vector<int>& mirror_axes, int& count) {
  std::vector<int> free_dof(3 * static_cast<size_t>(model.particle_count), -1);
  const double tolerance = 1e-9 * (model.rest_position.rowwise().maxCoeff() -
                                   model.rest_position.rowwise().minCoeff()).maxCoeff();
  for (int a : mirror_axes)
    if (a < 0 || a > 1) throw std::invalid_argument("held tool: a mirror axis is 0 (x) or 1 (y)");
  count = 0;
  for (int i = 0; i < model.particle_count; ++i)
    if (!model.fixed[i])
      for (int c = 0; c < 3; ++c) {
        bool on_mirror = false;
        for (int a : mirror_axes)
          on_mirror |= a == c && std::abs(model.rest_position(a, i) - model.indenter_start[a]) <= tolerance;
        if (!on_mirror) free_dof[3 * i + c] = count++;
      }
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
  // The solution before the last (for the secant predictor), once there is one.
  Points x_before;
  Vec3 centre_before;
  std::vector<double> pressure_before;
  bool has_before = false;
  Points x_last;                       // the last solution (x is overwritten by the predictor)
  std::vector<double> pressure_last;
  double penalty = 0.0;               // k of (5.8), N/m
  std::vector<double> lambda, pressure;  // per node: multiplier estimate, p_i at x
  Eigen::VectorXd residual, step;
  Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower> cholesky;
  bool pattern_analysed = false;

  Impl(const Model& m, const HeldToolOptions& o)
      : model(m), opt(o), free_dof(free_dofs_of(m, o.mirror_axes, free_count)), tangent(m, free_dof, free_count) {
    const double R = m.indenter_radius;
    const double E = m.lame_mu * (3 * m.lame_lambda + 2 * m.lame_mu) / (m.lame_lambda + m.lame_mu);
    if (opt.force_tolerance <= 0) opt.force_tolerance = 1e-9 * E * R * R;
    if (opt.gap_tolerance <= 0) opt.gap_tolerance = 1e-7 * R;
    if (opt.max_increment <= 0) opt.max_increment = 0.05 * R;
    x = m.rest_position;
    x_last = x;
    trial = x;
    f.setZero(3, m.particle_count);
    centre = m.indenter_start;
    lambda.assign(m.particle_count, 0.0);
    pressure.assign(m.particle_count, 0.0);
    pressure_last = pressure;
    residual.setZero(free_count);
    step.setZero(free_count);
    cholesky.cholmod().print = 0;  // an indefinite tangent is handled below, not printed
    // k of (5.8): the stiffest node's own stiffness at rest. A stiffer penalty gains more on
    // the penetration per augmentation, but Newton linearises max(0, lambda - k g) at the
    // kink: at 100 times it cycled among contact sets at nu = 0.45 (1 -> 13 pressed nodes and
    // back, the line search taking steps of 1e-6 to 1e-3) and stalled at a residual of
    // 2e-4 N; at 1 times it converges there in 40 iterations with two augmentations.
    SparseMatrix K;
    tangent.assemble(x, work, K);
    double diagonal = 0;
    for (int k = 0; k < K.outerSize(); ++k) diagonal = std::max(diagonal, K.coeff(k, k));
    penalty = diagonal;
  }

  // The start of the solve at c: the secant extrapolation of the last two solutions along
  // the tool's path, x + s (x - x_before), lambda = max(0, p + s (p - p_before)), with s the
  // ratio of the tool's steps (the last solution itself when there is no earlier one, or the
  // extrapolation inverts an element); then every free node inside the sphere, or kept pressed
  // by the extrapolation, is put on its surface along the radius. Without this each increment
  // begins with the tool's whole step as penetration under a stiff penalty, and Newton
  // wanders among contact sets before it converges. Only the path changes: the solution is
  // the same to the tolerances (tests/held_tool_static_test.cpp, docs/verification.md).
  void predict(const Vec3& c) {
    x = x_last;
    lambda = pressure_last;
    const double previous = (centre - centre_before).norm();
    if (has_before && previous > 0) {
      const double s = (c - centre).norm() / previous;
      trial = x_last + s * (x_last - x_before);
      if (std::isfinite(elastic_energy(model, trial))) {
        x.swap(trial);
        for (size_t i = 0; i < lambda.size(); ++i)
          lambda[i] = std::max(0.0, pressure_last[i] + s * (pressure_last[i] - pressure_before[i]));
      }
    }
    trial = x;
    for (int i = 0; i < model.particle_count; ++i) {
      if (model.fixed[i]) continue;
      const Vec3 offset = x.col(i) - c;
      const double distance = offset.norm();
      if (!(lambda[i] > 0 || distance < model.indenter_radius) || !(distance > 0)) continue;
      Vec3 moved = c + model.indenter_radius / distance * offset;
      for (int a = 0; a < 3; ++a)
        if (free_dof[3 * i + a] < 0) moved[a] = x(a, i);  // a mirror's component stays
      trial.col(i) = moved;
      // Pressed from the start where round-off leaves g <= 0 (p = lambda - k g > 0), so the
      // first tangent holds the node on the sphere instead of letting the step push it deep
      // into the penalty; where g comes out a hair positive the node starts free (slower only).
      lambda[i] = std::max(lambda[i], 1e-30);
    }
    if (std::isfinite(elastic_energy(model, trial)))
      x.swap(trial);
    else
      lambda = pressure_last;
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
      double squared = 0;
      for (int a = 0; a < 3; ++a)
        if (const int k = free_dof[3 * i + a]; k >= 0) residual[k] = r[a], squared += r[a] * r[a];
      worst = std::max(worst, std::sqrt(squared));  // a mirror's reaction is no residual
    }
    return worst;
  }

  // The 2-norm of the residual (5.7) over the free DOFs at positions y (uses f as scratch).
  double residual_norm_at(const Points& y, const Vec3& c) {
    elastic_forces(model, y, f);
    const double R = model.indenter_radius;
    double sum = 0;
    for (int i = 0; i < model.particle_count; ++i) {
      if (model.fixed[i]) continue;
      Vec3 r = f.col(i);
      const Vec3 offset = y.col(i) - c;
      const double p = std::max(0.0, lambda[i] - penalty * (offset.norm() - R));
      if (p > 0) r += p * offset.normalized();
      for (int a = 0; a < 3; ++a)
        if (free_dof[3 * i + a] >= 0) sum += r[a] * r[a];
    }
    return std::sqrt(sum);
  }

  bool newton_step(const Vec3& c, std::string& message) {
    SparseMatrix K;
    tangent.assemble(x, work, K);
    // + the contact term's Hessian on the pressed nodes (lower triangle; the node's own block
    // is in K's pattern): k n n^T - p_i (I - n n^T) / |x_i - c|. The second part, the sphere's
    // curvature under the pressure, keeps Newton quadratic (without it convergence is linear
    // at a rate of about p_i / (|x_i - c| K_ii)); far from equilibrium, where the penalty's
    // p_i are huge, it may make K indefinite, and then K is taken without it.
    auto contact_hessian = [&](bool curvature) {
      std::vector<Eigen::Triplet<double>> extra;
      for (int i = 0; i < model.particle_count; ++i) {
        if (model.fixed[i] || pressure[i] <= 0) continue;
        const Vec3 offset = x.col(i) - c;
        const double distance = offset.norm();
        const Vec3 n = offset / distance;
        Eigen::Matrix3d H = penalty * n * n.transpose();
        if (curvature) H -= pressure[i] / distance * (Eigen::Matrix3d::Identity() - n * n.transpose());
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b) {
            const int ka = free_dof[3 * i + a], kb = free_dof[3 * i + b];
            if (ka >= 0 && kb >= 0 && kb <= ka) extra.emplace_back(ka, kb, H(a, b));
          }
      }
      SparseMatrix P(free_count, free_count);
      P.setFromTriplets(extra.begin(), extra.end());
      return P;
    };
    const SparseMatrix elastic = K;
    K = elastic + contact_hessian(true);
    if (!pattern_analysed) {
      cholesky.analyzePattern(K);
      pattern_analysed = true;
    }
    cholesky.factorize(K);
    if (cholesky.info() != Eigen::Success) {
      K = elastic + contact_hessian(false);
      cholesky.factorize(K);
    }
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
    // Near convergence the merit's change is below its round-off (the energies of all bricks
    // summed): there a full step is taken when it lowers the residual's 2-norm, which the
    // Newton step does quadratically; a step of round-off size on the merit alone stalls.
    const double m0 = merit(x, c), slope = -residual.dot(step);
    const double r0 = residual.norm();
    double alpha = 1.0;
    for (int tries = 0; tries < 30; ++tries, alpha *= 0.5) {
      trial = x;
      for (int i = 0; i < model.particle_count; ++i)
        for (int a = 0; a < 3; ++a)
          if (const int k = free_dof[3 * i + a]; k >= 0) trial(a, i) += alpha * step[k];
      const double m1 = merit(trial, c);
      if (m1 <= m0 + 1e-4 * alpha * slope) break;
      if (std::isfinite(m1) && std::abs(m1 - m0) <= 1e-9 * std::abs(m0)) {
        if (tries == 0 && residual_norm_at(trial, c) < r0) break;
        if (std::abs(m1 - m0) <= 1e-12 * std::abs(m0)) break;
      }
    }
    spdlog::trace("held tool:     step with alpha {:.3g}, shift {:.1e}, {} pressed", alpha, shift,
                  std::count_if(pressure.begin(), pressure.end(), [](double p) { return p > 0; }));
    x.swap(trial);
    return true;
  }

  void solve_at(const Vec3& c, HeldToolSolution& sol) {
    for (int aug = 0; aug < opt.max_augmentations; ++aug) {
      bool inner = false;
      for (int it = 0; it <= opt.max_newton; ++it) {
        sol.residual = compute_residual(c);
        spdlog::trace("held tool:     Newton {} residual {:.3e} N", it, sol.residual);
        if (sol.residual <= opt.force_tolerance) {
          inner = true;
          break;
        }
        if (it == opt.max_newton) break;
        ++sol.newton_iterations;
        if (!newton_step(c, sol.message)) return;
      }
      spdlog::debug("held tool: augmentation {} at centre z {:.6g} m: {} Newton iterations, residual {:.3e} N", aug,
                    c[2], sol.newton_iterations, sol.residual);
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
      spdlog::debug("held tool:   penetration {:.3e} m", penetration);
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
    s.predict(c);
    s.solve_at(c, sol);
    if (!sol.converged) {
      sol.message = "at the increment " + std::to_string(k) + " of " + std::to_string(increments) + ": " + sol.message;
      return sol;
    }
    s.x_before = s.x_last;
    s.pressure_before = s.pressure_last;
    s.centre_before = s.centre;
    s.has_before = true;
    s.x_last = s.x;
    s.pressure_last = s.pressure;
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
