#include "analysis/static_contact.h"

#include <Eigen/Cholesky>
#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <spdlog/spdlog.h>
#include <stdexcept>

#include "core/contact.h"
#include "analysis/rest.h"
#include "core/checkpoint.h"
#include "core/health.h"
#include "core/indentation.h"
#include "core/integrators.h"
#include "core/solid.h"
#include "core/step.h"

namespace palpate {

bool has_linear_static_solve(const Model& model) {
  return model.solid == SolidKind::hex_fem && model.hex.formulation == HexFormulation::linear;
}

// ---------------------------------------------------------------------------
// Linear FEM: exact active-set solve on the compliance of the contact candidates.

struct LinearStaticContact::Impl {
  using SparseMatrix = Eigen::SparseMatrix<double>;
  const Model* model = nullptr;  // the hex FEM model, when built from one (write_state needs it)
  LinearBody body;
  std::vector<int> free_dof;   // 3n: index among the free DOFs, -1 for a fixed particle
  int free_count = 0;
  Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower> cholesky;

  // Candidates (body.candidate): free surface nodes under the sphere, with their undeformed gaps h at d = 0.
  const std::vector<int>& candidate = body.candidate;
  std::vector<double> gap0;    // h_i, m
  // Compliance columns C(:, k) restricted to the candidates' vertical DOFs; empty until needed.
  std::vector<std::vector<double>> column;
  int columns_computed = 0;
  std::vector<int> active;     // candidate indices; kept between solves as a warm start

  explicit Impl(const Model& m) : model(&m) {
    if (!has_linear_static_solve(m))
      throw std::runtime_error("the exact quasi-static solve needs the linear hex_fem model");
    body.rest_position = m.rest_position;
    body.fixed = m.fixed;
    body.indenter_radius = m.indenter_radius;
    body.site_x = m.indenter_start[0];
    body.site_y = m.indenter_start[1];
    body.touch_height = m.touch_height;
    hex_stiffness(m, body.stiffness_lower);
    top_face_candidates(m, body.candidate);
    if (body.candidate.empty()) throw std::runtime_error("no free top-face node lies under the indenter");
    set_up();
  }

  explicit Impl(LinearBody b) : body(std::move(b)) {
    const Eigen::Index n = body.rest_position.cols();
    const double R = body.indenter_radius;
    if (static_cast<Eigen::Index>(body.fixed.size()) != n)
      throw std::invalid_argument("LinearBody: fixed has " + std::to_string(body.fixed.size()) + " entries for " +
                                  std::to_string(n) + " nodes");
    if (!(R > 0.0)) throw std::invalid_argument("LinearBody: the indenter radius must be positive");
    if (body.candidate.empty()) throw std::invalid_argument("LinearBody: no contact candidate");
    for (int i : body.candidate) {
      if (i < 0 || i >= n || body.fixed[i])
        throw std::invalid_argument("LinearBody: candidate " + std::to_string(i) + " is not a free node");
      const double dx = body.rest_position(0, i) - body.site_x, dy = body.rest_position(1, i) - body.site_y;
      if (dx * dx + dy * dy >= R * R)
        throw std::invalid_argument("LinearBody: candidate " + std::to_string(i) + " is outside the sphere's footprint");
    }
    set_up();
    for (size_t k = 0; k < gap0.size(); ++k)
      if (gap0[k] < -1e-9 * R)
        throw std::invalid_argument("LinearBody: candidate " + std::to_string(candidate[k]) +
                                    " lies above the sphere at first touch (gap " + std::to_string(gap0[k]) + " m)");
  }

  void set_up() {
    const Eigen::Index n = body.rest_position.cols();
    free_dof.assign(3 * static_cast<size_t>(n), -1);
    for (Eigen::Index i = 0; i < n; ++i)
      if (!body.fixed[i])
        for (int c = 0; c < 3; ++c) free_dof[3 * i + c] = free_count++;
    factorize();
    const Points& X = body.rest_position;
    const double R = body.indenter_radius;
    for (int i : candidate) {
      const double dx = X(0, i) - body.site_x, dy = X(1, i) - body.site_y;
      // Sphere bottom at the node when the indenter touches the surface: touch_height - sqrt(R^2 - r^2).
      gap0.push_back(body.touch_height - std::sqrt(R * R - dx * dx - dy * dy) - X(2, i));
    }
    column.resize(candidate.size());
  }

  // Lower triangle of K over all DOFs from the hex element matrices.
  static void hex_stiffness(const Model& model, std::vector<Eigen::Triplet<double>>& triplets) {
    triplets.reserve(static_cast<size_t>(model.hex.element_count) * 300);
    for (int e = 0; e < model.hex.element_count; ++e) {
      const auto& nodes = model.hex.element_nodes[e];
      const ElementMatrix& K = model.hex.element_stiffness[model.hex.element_type[e]];
      for (int a = 0; a < 8; ++a)
        for (int c = 0; c < 3; ++c) {
          const int row = 3 * nodes[a] + c;
          for (int b = 0; b < 8; ++b)
            for (int d = 0; d < 3; ++d) {
              const int col = 3 * nodes[b] + d;
              if (row >= col) triplets.emplace_back(row, col, K(3 * a + c, 3 * b + d));
            }
        }
    }
  }

  // K over the free DOFs (the body's entries on fixed DOFs dropped), factorised.
  void factorize() {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(body.stiffness_lower.size());
    for (const auto& t : body.stiffness_lower) {
      const int row = free_dof[t.row()], col = free_dof[t.col()];
      if (row >= 0 && col >= 0) triplets.emplace_back(std::max(row, col), std::min(row, col), t.value());
    }
    body.stiffness_lower = {};
    SparseMatrix K(free_count, free_count);
    K.setFromTriplets(triplets.begin(), triplets.end());
    triplets = {};
    cholesky.compute(K);
    if (cholesky.info() != Eigen::Success)
      throw std::runtime_error("the stiffness matrix is singular: the fixed faces do not hold the body");
  }

  // The hex model's candidates: free top-face nodes under the sphere.
  static void top_face_candidates(const Model& model, std::vector<int>& candidate) {
    const Points& X = model.rest_position;
    const double top = X.row(2).maxCoeff();
    const double R = model.indenter_radius;
    const double tol = 1e-9 * std::max(1.0, std::abs(top));
    for (int i = 0; i < model.particle_count; ++i) {
      if (model.fixed[i] || X(2, i) < top - tol) continue;
      const double dx = X(0, i) - model.indenter_start[0], dy = X(1, i) - model.indenter_start[1];
      if (dx * dx + dy * dy < R * R) candidate.push_back(i);
    }
  }

  // Solves K x = b for the unit vertical loads of the candidates in `need` (batched).
  void compute_columns(const std::vector<int>& need) {
    constexpr int kBatch = 64;
    const int m = static_cast<int>(candidate.size());
    for (size_t start = 0; start < need.size(); start += kBatch) {
      const int b = static_cast<int>(std::min<size_t>(kBatch, need.size() - start));
      Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(free_count, b);
      for (int k = 0; k < b; ++k) rhs(free_dof[3 * candidate[need[start + k]] + 2], k) = 1.0;
      const Eigen::MatrixXd x = cholesky.solve(rhs);
      for (int k = 0; k < b; ++k) {
        std::vector<double>& col = column[need[start + k]];
        col.resize(m);
        for (int j = 0; j < m; ++j) col[j] = x(free_dof[3 * candidate[j] + 2], k);
        ++columns_computed;
      }
    }
  }

  StaticSolution solve(double force, State* state) {
    StaticSolution out;
    if (!(force >= 0.0) || !std::isfinite(force)) {
      out.message = "the force must be finite and >= 0";
      return out;
    }
    const int m = static_cast<int>(candidate.size());
    if (active.empty()) active = {static_cast<int>(std::min_element(gap0.begin(), gap0.end()) - gap0.begin())};
    std::vector<uint8_t> in_active(m, 0);
    Eigen::VectorXd p;
    double d = 0.0;
    const double gap_tolerance = 1e-12 * body.indenter_radius;
    const int max_iterations = 20 * m + 100;
    for (int it = 0; it < max_iterations; ++it) {
      out.iterations = it;
      std::vector<int> need;
      for (int a : active)
        if (column[a].empty()) need.push_back(a);
      compute_columns(need);
      const int na = static_cast<int>(active.size());
      // w_A = 0 and sum p = F: C_AA p = d 1 - h_A, so p = d y1 - yh with y1 = C_AA^-1 1,
      // yh = C_AA^-1 h_A, and d = (F + 1.yh) / (1.y1).
      Eigen::MatrixXd S(na, na);
      Eigen::VectorXd h(na);
      for (int a = 0; a < na; ++a) {
        h[a] = gap0[active[a]];
        for (int b = 0; b < na; ++b) S(a, b) = 0.5 * (column[active[b]][active[a]] + column[active[a]][active[b]]);
      }
      const Eigen::LDLT<Eigen::MatrixXd> ldlt(S);
      const Eigen::VectorXd y1 = ldlt.solve(Eigen::VectorXd::Ones(na));
      const Eigen::VectorXd yh = ldlt.solve(h);
      d = (force + yh.sum()) / y1.sum();
      p = d * y1 - yh;
      // A node pulling on the sphere leaves the active set (the most negative first).
      Eigen::Index worst;
      if (na > 1 && p.minCoeff(&worst) < -1e-12 * std::max(force, 1e-300)) {
        active.erase(active.begin() + worst);
        continue;
      }
      // Nodes penetrating the sphere join it.
      std::fill(in_active.begin(), in_active.end(), 0);
      for (int a : active) in_active[a] = 1;
      std::vector<int> join;
      out.max_penetration = 0.0;
      for (int j = 0; j < m; ++j) {
        if (in_active[j]) continue;
        double w = gap0[j] - d;
        for (int a = 0; a < na; ++a) w += column[active[a]][j] * p[a];
        out.max_penetration = std::max(out.max_penetration, -w);
        if (w < -gap_tolerance) join.push_back(j);
      }
      if (join.empty()) {
        out.converged = true;
        break;
      }
      active.insert(active.end(), join.begin(), join.end());
    }
    if (!out.converged) out.message = "the active set did not settle";
    out.indentation = d;
    out.contact_force = p.sum();
    out.active_count = static_cast<int>(active.size());
    if (state) {
      if (!model) throw std::logic_error("LinearStaticContact::solve: a body without a Model has no State to write");
      write_state(force, d, p, *state);
    }
    return out;
  }

  void write_state(double force, double d, const Eigen::VectorXd& p, State& state) {
    const Model& model = *this->model;
    Eigen::VectorXd load = Eigen::VectorXd::Zero(free_count);
    for (size_t a = 0; a < active.size(); ++a) load[free_dof[3 * candidate[active[a]] + 2]] = -p[a];
    const Eigen::VectorXd u = cholesky.solve(load);
    state.position = model.rest_position;
    for (int i = 0; i < model.particle_count; ++i)
      for (int c = 0; c < 3; ++c)
        if (free_dof[3 * i + c] >= 0) state.position(c, i) += u[free_dof[3 * i + c]];
    state.velocity.setZero();
    state.indenter_center = Vec3(model.indenter_start[0], model.indenter_start[1], model.touch_height - d);
    state.indenter_velocity.setZero();
    state.force_command = press_down(force);
    state.contact_index.clear();
    state.contact_normal_force.clear();
    for (size_t a = 0; a < active.size(); ++a) {
      state.contact_force.col(static_cast<Eigen::Index>(a)) = Vec3(0, 0, -p[a]);
      state.contact_index.push_back(candidate[active[a]]);
      state.contact_normal_force.push_back(p[a]);
    }
    state.indenter_contact_force = Vec3(0, 0, p.sum());
  }
};

LinearStaticContact::LinearStaticContact(const Model& model) : impl_(std::make_unique<Impl>(model)) {}
LinearStaticContact::LinearStaticContact(LinearBody body) : impl_(std::make_unique<Impl>(std::move(body))) {}
LinearStaticContact::~LinearStaticContact() = default;
StaticSolution LinearStaticContact::solve(double force, State* state) { return impl_->solve(force, state); }
int LinearStaticContact::free_dofs() const { return impl_->free_count; }
int LinearStaticContact::candidate_count() const { return static_cast<int>(impl_->candidate.size()); }
int LinearStaticContact::columns_computed() const { return impl_->columns_computed; }

// ---------------------------------------------------------------------------
// Nonlinear models: pseudo-transient continuation with the implicit Euler step.

StaticSolution relax_to_rest(const Model& model, const Options& opt, const RestSpec& rest, State& state, double force,
                             double residual_tolerance, int max_steps) {
  StaticSolution out;
  if (!(force >= 0.0) || !std::isfinite(force)) {
    out.message = "the force must be finite and >= 0";
    return out;
  }
  // The continuation runs with options of its own: implicit Euler without damping, and
  // an indenter that weighs as much as the body (the masses only regularise the
  // steps; a light sphere's free motion would overshoot at large dt). A step whose
  // residual grows is rejected (the checkpoint puts the state back) and retried with
  // half the step; an accepted one doubles it.
  Options relax = opt;
  relax.integrator.type = IntegratorType::implicit_euler;
  relax.integrator.max_interval = 1;  // subcycling is symplectic Euler's
  relax.integrator.damping = 0.0;
  relax.indenter_mass = std::max(opt.indenter_mass, std::accumulate(model.mass.begin(), model.mass.end(), 0.0));
  state.force_command = press_down(force);
  double& dt = relax.integrator.dt;
  const double dt_max = 1e4, dt_min = 1e-9;
  Points f(3, model.particle_count);
  auto residual_of = [&](const State& s) {  // free particles' net force and the indenter's imbalance, N
    elastic_forces(model, s.position, f);
    add_contact_forces(s, f);
    double r = 0.0;
    for (int i = 0; i < model.particle_count; ++i)
      if (!model.fixed[i]) r = std::max(r, f.col(i).norm());
    return std::max(r, (s.indenter_contact_force + s.force_command).cwiseProduct(tool_axes(relax)).norm());
  };
  state.velocity.setZero();
  state.indenter_velocity.setZero();
  double residual = residual_of(state);
  const double target = residual_tolerance * std::max(force, 1e-300);
  int rejected_in_a_row = 0;
  Checkpoint accepted(state);
  for (int k = 0; k < max_steps && residual > target; ++k) {
    accepted.save(state);
    state.velocity.setZero();
    state.indenter_velocity.setZero();
    const StepStatus status = step(model, relax, state);
    out.iterations = k + 1;
    const double next = status == StepStatus::non_finite ? INFINITY : residual_of(state);
    spdlog::debug("relax_to_rest: step {} dt {:.3g} s residual {:.3e} N d {:.6f} m contact {:.4f} N ({} nodes)", k, dt,
                  next, indentation(model, state), state.indenter_contact_force[2], state.contact_index.size());
    if (!(next < residual)) {  // reject: restore and halve the step
      accepted.restore(state);
      dt *= 0.5;
      if (dt < dt_min || ++rejected_in_a_row > 6) break;  // stalled: the dynamic settle finishes
      continue;
    }
    residual = next;
    rejected_in_a_row = 0;
    dt = std::min(dt_max, 2.0 * dt);
  }
  state.velocity.setZero();
  state.indenter_velocity.setZero();
  // The continuation's energy bookkeeping (its heavy indenter) is not the caller's.
  reset_health(model, opt, state);
  out.converged = residual <= target;
  if (!out.converged) {
    // Polish with the scene's own damped dynamics (the dynamic settle of palpate-verify).
    const PressResult press = press_to_rest(model, opt, rest, state, force);
    out.iterations += static_cast<int>(press.steps);
    out.converged = press.at_rest;
    if (!press.at_rest) out.message = "neither the continuation nor the dynamic settle reached rest";
  }
  out.indentation = indentation(model, state);
  out.contact_force = state.indenter_contact_force[2];
  out.active_count = static_cast<int>(state.contact_index.size());
  return out;
}

StaticSolution relax_to_rest_at(const Model& model, const Options& opt, State& state, const Vec3& tool_position,
                                double residual_tolerance, double contact_tolerance, int max_steps) {
  StaticSolution out;
  if (!tool_position.allFinite()) {
    out.message = "the tool position must be finite";
    return out;
  }
  // Implicit Euler steps without damping (Newton steps regularised by M / dt^2, with the
  // exact coupled contact solve), the tool so heavy that neither its free motion nor the
  // contact projection moves it, and put back exactly after each step. A step whose
  // residual grows is rejected and retried with half the step; an accepted one doubles it.
  Options relax = opt;
  relax.integrator.type = IntegratorType::implicit_euler;
  relax.integrator.max_interval = 1;  // subcycling is symplectic Euler's
  relax.integrator.damping = 0.0;
  relax.tool_guide = ToolGuide::free;
  relax.coupling = CouplingOptions{};
  relax.indenter_mass = 1e30;
  relax.health.enabled = false;
  relax.contact.tolerance = contact_tolerance;
  relax.contact.max_iterations = std::max(relax.contact.max_iterations, 4 * model.particle_count);
  relax.integrator.cg_tolerance = std::min(relax.integrator.cg_tolerance, 1e-10);
  relax.integrator.cg_max_iterations = std::max(relax.integrator.cg_max_iterations, 4 * model.particle_count);
  state.force_command.setZero();
  double& dt = relax.integrator.dt;
  const double dt_max = 1e4, dt_min = 1e-9;
  Points f(3, model.particle_count);
  auto hold = [&](State& s) {
    s.indenter_center = tool_position;
    s.indenter_velocity.setZero();
    s.velocity.setZero();
  };
  auto residual_of = [&](const State& s) {  // the free particles' largest net force, N
    elastic_forces(model, s.position, f);
    add_contact_forces(s, f);
    for (int i = 0; i < model.particle_count; ++i)
      if (!model.fixed[i]) f.col(i) += model.mass[i] * opt.gravity;
    double r = 0.0;
    for (int i = 0; i < model.particle_count; ++i)
      if (!model.fixed[i]) r = std::max(r, f.col(i).norm());
    return r;
  };
  hold(state);
  // The first step's contact solve finds the contact set at the held position; until it
  // has run, the residual of the carried contact forces means nothing.
  double residual = INFINITY;
  int rejected_in_a_row = 0;
  Checkpoint accepted(state);
  // The tolerance is relative to the force on the tool (an absolute floor when there is none).
  auto target = [&] { return residual_tolerance * std::max(state.indenter_contact_force.norm(), 1e-3); };
  for (int k = 0; k < max_steps && residual > target(); ++k) {
    accepted.save(state);
    const StepStatus status = step(model, relax, state);
    hold(state);
    out.iterations = k + 1;
    const double next = status == StepStatus::non_finite ? INFINITY : residual_of(state);
    spdlog::debug("relax_to_rest_at: step {} dt {:.3g} s residual {:.3e} N contact ({:.4f}, {:.4f}, {:.4f}) N ({} nodes)",
                  k, dt, next, state.indenter_contact_force[0], state.indenter_contact_force[1],
                  state.indenter_contact_force[2], state.contact_index.size());
    if (!(next < residual)) {
      accepted.restore(state);
      dt *= 0.5;
      if (dt < dt_min || ++rejected_in_a_row > 12) break;
      continue;
    }
    residual = next;
    rejected_in_a_row = 0;
    dt = std::min(dt_max, 2.0 * dt);
  }
  hold(state);
  reset_health(model, opt, state);
  out.converged = residual <= target();
  if (!out.converged)
    out.message = fmt::format("the continuation stalled at a residual of {:.3e} N (tolerance {:.3e} N)", residual,
                              target());
  out.indentation = indentation(model, state);
  out.contact_force = state.indenter_contact_force[2];
  out.active_count = static_cast<int>(state.contact_index.size());
  for (size_t a = 0; a < state.contact_index.size(); ++a) {
    const int i = state.contact_index[a];
    out.max_penetration =
        std::max(out.max_penetration, model.indenter_radius - (state.position.col(i) - tool_position).norm());
  }
  return out;
}

}  // namespace palpate
