#include "core/contact.h"

#include "core/integrators.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <optional>

namespace palpate {

namespace {

// In-place Cholesky factorisation of the k x k SPD matrix L (row-major, lower
// triangle used) and solve L L^T x = b. Returns false if not positive definite.
bool cholesky_solve(int k, double* L, double* b) {
  for (int r = 0; r < k; ++r) {
    for (int c = 0; c <= r; ++c) {
      double s = L[r * k + c];
      for (int q = 0; q < c; ++q) s -= L[r * k + q] * L[c * k + q];
      if (r == c) {
        if (s <= 0) return false;
        L[r * k + r] = std::sqrt(s);
      } else {
        L[r * k + c] = s / L[c * k + c];
      }
    }
  }
  for (int r = 0; r < k; ++r) {  // forward
    double s = b[r];
    for (int q = 0; q < r; ++q) s -= L[r * k + q] * b[q];
    b[r] = s / L[r * k + r];
  }
  for (int r = k - 1; r >= 0; --r) {  // backward
    double s = b[r];
    for (int q = r + 1; q < k; ++q) s -= L[q * k + r] * b[q];
    b[r] = s / L[r * k + r];
  }
  return true;
}

// The operator of a principal pivoting solve (principal_pivoting below). Two of them: the
// dense W of implicit Euler's splitting and of the analysis, and the explicit integrators'
// W = D + U U^T of (2.4), solved through (2.19) at O(m) a pivot. Each provides
//   solve_active(k, members, b): b := W_AA^-1 b (A = members[0..k)), false if W_AA is not SPD;
//     the solution becomes the operator's current lambda_A (for coupling());
//   coupling(a): (W_aA lambda_A) for a candidate a outside A;
//   diagonal(a), start(lambda), row_product(a, lambda) = (W lambda)_a, moved(a, delta) for
//     projected Gauss-Seidel, which changes lambda one entry at a time.
class DenseDelassus {
 public:
  DenseDelassus(int m, const double* W, Workspace& work) : m_(m), W_(W) {
    if (work.solve_buffer.size() < static_cast<size_t>(m) * m) work.solve_buffer.resize(static_cast<size_t>(m) * m);
    L_ = work.solve_buffer.data();
  }
  bool solve_active(int k, const int* members, double* b) {
    for (int r = 0; r < k; ++r)
      for (int c = 0; c <= r; ++c) L_[r * k + c] = W_[members[r] * m_ + members[c]];
    members_ = members;
    k_ = k;
    lambda_ = b;
    return k == 0 || cholesky_solve(k, L_, b);
  }
  double coupling(int a) const {
    double w = 0.0;
    for (int r = 0; r < k_; ++r) w += W_[a * m_ + members_[r]] * lambda_[r];
    return w;
  }
  double diagonal(int a) const { return W_[a * m_ + a]; }
  void start(const double*, int) {}
  double row_product(int a, const double* lambda) const {
    double w = 0.0;
    for (int b = 0; b < m_; ++b) w += W_[a * m_ + b] * lambda[b];
    return w;
  }
  void moved(int, double) {}

 private:
  int m_;
  const double* W_;
  double* L_ = nullptr;
  const int* members_ = nullptr;
  const double* lambda_ = nullptr;
  int k_ = 0;
};

// W = D + U U^T (2.4) with D = diag(d) > 0 and U of three columns (u: row a at u + 3a).
// W_AA^-1 b by the Woodbury identity (2.19): y = D_A^-1 b, G = I + U_A^T D_A^-1 U_A (3 x 3),
// W_AA^-1 b = y - D_A^-1 U_A G^-1 U_A^T y.
class LumpedDelassus {
 public:
  LumpedDelassus(const double* d, const double* u) : d_(d), u_(u) {}
  bool solve_active(int k, const int* members, double* b) {
    // G's lower triangle and t = U_A^T y, accumulated by hand (Eigen's rankUpdate of a
    // 3 x 3 is an out-of-line call per row, most of a pivot's cost).
    double g00 = 1, g10 = 0, g11 = 1, g20 = 0, g21 = 0, g22 = 1;
    double t0 = 0, t1 = 0, t2 = 0;
    for (int r = 0; r < k; ++r) {
      const int a = members[r];
      const double inv_d = 1.0 / d_[a];
      const double ux = u_[3 * a], uy = u_[3 * a + 1], uz = u_[3 * a + 2];
      const double y = b[r] * inv_d;
      b[r] = y;
      g00 += ux * ux * inv_d, g10 += uy * ux * inv_d, g11 += uy * uy * inv_d;
      g20 += uz * ux * inv_d, g21 += uz * uy * inv_d, g22 += uz * uz * inv_d;
      t0 += ux * y, t1 += uy * y, t2 += uz * y;
    }
    Eigen::Matrix3d G;
    G << g00, 0, 0, g10, g11, 0, g20, g21, g22;
    const Eigen::LLT<Eigen::Matrix3d> llt(G);  // reads the lower triangle
    if (llt.info() != Eigen::Success) return false;
    const Vec3 z = llt.solve(Vec3(t0, t1, t2));
    double s0 = 0, s1 = 0, s2 = 0;  // U_A^T lambda_A, for coupling()
    for (int r = 0; r < k; ++r) {
      const int a = members[r];
      const double ux = u_[3 * a], uy = u_[3 * a + 1], uz = u_[3 * a + 2];
      const double lambda = b[r] - (ux * z[0] + uy * z[1] + uz * z[2]) / d_[a];
      b[r] = lambda;
      s0 += ux * lambda, s1 += uy * lambda, s2 += uz * lambda;
    }
    s_ = Vec3(s0, s1, s2);
    return true;
  }
  double coupling(int a) const { return row(a).dot(s_); }
  double diagonal(int a) const { return d_[a] + row(a).squaredNorm(); }
  void start(const double* lambda, int m) {
    s_.setZero();
    for (int a = 0; a < m; ++a) s_ += row(a) * lambda[a];
  }
  double row_product(int a, const double* lambda) const { return d_[a] * lambda[a] + row(a).dot(s_); }
  void moved(int a, double delta) { s_ += row(a) * delta; }
  // out = W x over m candidates.
  void apply(int m, const double* x, double* out) {
    start(x, m);
    for (int a = 0; a < m; ++a) out[a] = row_product(a, x);
  }

 private:
  Vec3 row(int a) const { return Vec3(u_[3 * a], u_[3 * a + 1], u_[3 * a + 2]); }
  const double* d_;
  const double* u_;
  Vec3 s_ = Vec3::Zero();
};

template <class Op>
int projected_gauss_seidel(int m, Op& W, const double* g, double* lambda, double tolerance, int max_sweeps) {
  for (int sweep = 1; sweep <= max_sweeps; ++sweep) {
    double worst = 0;
    for (int a = 0; a < m; ++a) {
      const double w = g[a] + W.row_product(a, lambda);
      const double updated = std::max(0.0, lambda[a] - w / W.diagonal(a));
      if (updated > 0 || w < 0) worst = std::max(worst, std::abs(w));
      W.moved(a, updated - lambda[a]);
      lambda[a] = updated;
    }
    if (worst <= tolerance) return sweep;
  }
  return -1;
}

// Block principal pivoting (docs/physics.md §2, "The LCP solver"; Judice and Pires 1994):
// guess the active set A ({g < 0} unless given), solve W_AA lambda_A = -g_A, and find the
// infeasible candidates: members with a negative multiplier, others whose gap
// w_a = g_a + (W lambda)_a is violated beyond the tolerance. None: solved. Otherwise flip
// them all (a block pivot) while their number keeps falling to a new low, or for
// kBlockPivotTries more pivots; then flip only the lowest-indexed one (Murty's rule, finite
// for the positive definite W) until the number falls below its low again. Projected
// Gauss-Seidel finishes if max_iterations pivots do not settle it.
constexpr int kBlockPivotTries = 3;

template <class Op>
int principal_pivoting(int m, Op& W, const double* g, double* lambda, double tolerance, int max_iterations,
                       Workspace& work, const int* initial_active) {
  std::vector<int>& active = work.active;
  active.assign(m, 0);
  if (work.pivot_rhs.size() < static_cast<size_t>(m)) work.pivot_rhs.resize(m);
  double* rhs = work.pivot_rhs.data();
  work.members.resize(m);
  int* members = work.members.data();
  work.infeasible.resize(m);
  int* infeasible = work.infeasible.data();
  for (int a = 0; a < m; ++a) active[a] = initial_active ? initial_active[a] != 0 : g[a] < 0;
  int fewest = m + 1, tries = kBlockPivotTries;
  for (int iteration = 1; iteration <= max_iterations; ++iteration) {
    int k = 0;
    for (int a = 0; a < m; ++a)
      if (active[a]) members[k++] = a;
    for (int r = 0; r < k; ++r) rhs[r] = -g[members[r]];
    std::fill(lambda, lambda + m, 0.0);
    if (!W.solve_active(k, members, rhs)) break;
    for (int r = 0; r < k; ++r) lambda[members[r]] = rhs[r];
    int count = 0;
    for (int a = 0; a < m; ++a)
      if (active[a] ? lambda[a] < 0 : g[a] + W.coupling(a) < -tolerance) infeasible[count++] = a;
    if (count == 0) return iteration;
    if (count < fewest) {
      fewest = count;
      tries = kBlockPivotTries;
    } else if (tries > 0) {
      --tries;
    } else {
      count = 1;  // Murty: the lowest index only
    }
    for (int c = 0; c < count; ++c) active[infeasible[c]] ^= 1;
  }
  // Pivoting did not settle: finish with projected Gauss-Seidel from the clipped iterate.
  for (int a = 0; a < m; ++a) lambda[a] = std::max(0.0, lambda[a]);
  W.start(lambda, m);
  const int sweeps = projected_gauss_seidel(m, W, g, lambda, tolerance, 100 * max_iterations);
  return sweeps < 0 ? -1 : max_iterations + sweeps;
}

}  // namespace

int solve_signorini_lcp(int m, const double* W, const double* g, double* lambda, double tolerance,
                        int max_iterations, Workspace& work, const int* initial_active) {
  DenseDelassus op(m, W, work);
  return principal_pivoting(m, op, g, lambda, tolerance, max_iterations, work, initial_active);
}

int solve_signorini_lcp_lumped(int m, const double* d, const double* u, const double* g, double* lambda,
                               double tolerance, int max_iterations, Workspace& work, const int* initial_active) {
  LumpedDelassus op(d, u);
  return principal_pivoting(m, op, g, lambda, tolerance, max_iterations, work, initial_active);
}

namespace {

// Implicit Euler's coupled contact (docs/physics.md §2, (2.17), (2.18)).
constexpr double kColumnTolerance = 1e-4;  // residual of a cached column's CG solve (unit load), N
constexpr double kDirectionTurn = 0.99863;  // cos 3°: a column whose candidate's normal turned further is recomputed
constexpr int64_t kKeepSolves = 100;        // a cached particle no candidate for this many solves is dropped
constexpr int kJudgeAfter = 3;              // splitting iterations before W~ is judged by its contraction:
constexpr double kSlowContraction = 0.25;  // |nu_k+1 - nu_k| above this of the previous step: every column
                                           // is recomputed to cg_tolerance (once a solve)
constexpr int kMaxSplitting = 16;           // splitting iterations before the solve gives up
constexpr double kSplittingTolerance = 1.0;  // converged: |nu_k+1 - nu_k| <= this cg_tolerance max(|nu|, |p|)

// The LCPs of an implicit step, w = q + W (nu - p) >= 0, nu >= 0, nu . w = 0, with the Delassus
// operator of the step's A: W (nu - p) = dt^2 J u + the tool's part, u = A^-1 J^T (nu - p)
// (work.contact_response). They are solved by the splitting (2.18) on the approximation W~
// of (2.17) in work.delassus: one CG solve per iteration.
class CoupledContact {
 public:
  CoupledContact(const Model& model, const Options& opt, State& state, LinearResponse& A)
      : model_(model), opt_(opt), state_(state), work_(state.work), A_(A), m_(static_cast<int>(state.out.contact_candidate.size())),
        dt2_(opt.integrator.dt * opt.integrator.dt), inv_sphere_mass_(1.0 / tool_effective_mass(opt)),
        axes_(tool_axes(opt)) {
    const size_t m = static_cast<size_t>(m_);
    if (work_.splitting.size() < 4 * m) work_.splitting.resize(4 * m);
    if (work_.guess.size() < m) work_.guess.resize(m);
  }

  // (2.17): makes the cache hold a column of every candidate, computing those it does not
  // hold, those whose direction turned by more than kDirectionTurn and, with `all`, every
  // one (the CG to `tolerance`, N per unit load), then writes W~ (body and tool) to work.delassus.
  void load_columns(bool all, double tolerance) {
    ComplianceCache& c = work_.compliance;
    const std::vector<int>& candidate = state_.out.contact_candidate;
    if (c.slot.size() != static_cast<size_t>(model_.particle_count)) c.slot.assign(model_.particle_count, -1);
    if (c.dt != opt_.integrator.dt || c.damping != opt_.integrator.damping) {  // another A: start again
      for (int s = 0; s < c.capacity; ++s)
        if (c.particle[s] >= 0) c.slot[c.particle[s]] = -1;
      std::fill(c.particle.begin(), c.particle.end(), -1);
      c.dt = opt_.integrator.dt;
      c.damping = opt_.integrator.damping;
    }
    if (!all) {
      ++c.solves;
      for (int s = 0; s < c.capacity; ++s)  // drop the particles that stopped being candidates long ago
        if (c.particle[s] >= 0 && c.last_used[s] < c.solves - kKeepSolves) {
          c.slot[c.particle[s]] = -1;
          c.particle[s] = -1;
        }
    }
    for (int a = 0; a < m_; ++a) {
      const int i = candidate[a];
      const Vec3 n = work_.normal.col(a);
      int s = c.slot[i];
      const bool cached = s >= 0;
      if (!cached) s = allocate_slot(i);
      c.last_used[s] = c.solves;
      if (cached && !all && n.dot(c.direction.col(s)) >= kDirectionTurn) continue;
      // The column of particle i: dt^2 n_t . (A^-1 n)_t at every cached particle t.
      work_.rhs.setZero();
      work_.rhs.col(i) = n;
      count_solve(A_.solve(work_.rhs, work_.dv, tolerance));
      ++state_.out.contact_columns;
      c.direction.col(s) = n;
      const int cap = c.capacity;
      for (int t = 0; t < cap; ++t) {
        if (c.particle[t] < 0) continue;
        const double e = dt2_ * c.direction.col(t).dot(work_.dv.col(c.particle[t]));
        c.entry[static_cast<size_t>(t) * cap + s] = c.entry[static_cast<size_t>(s) * cap + t] = e;
      }
    }
    // W~ = the cached body part + the tool's part (2.4).
    const int cap = c.capacity;
    double* W = work_.delassus.data();
    for (int a = 0; a < m_; ++a) {
      const size_t row = static_cast<size_t>(c.slot[candidate[a]]) * cap;
      for (int b = 0; b < m_; ++b)
        W[a * m_ + b] = c.entry[row + c.slot[candidate[b]]] + tool_part(a, work_.normal.col(b));
    }
  }

  // w = q + W (nu - p) with u = A^-1 J^T (nu - p) current (q = inf stays inf).
  void residual(const double* q, const double* nu, double* w) const {
    const double* p = work_.previous_multiplier.data();
    Vec3 sphere = Vec3::Zero();
    for (int b = 0; b < m_; ++b) sphere += (nu[b] - p[b]) * axes_.cwiseProduct(work_.normal.col(b));
    for (int a = 0; a < m_; ++a) {
      const Vec3 n = work_.normal.col(a);
      w[a] = q[a] + dt2_ * (n.dot(work_.contact_response.col(state_.out.contact_candidate[a])) + inv_sphere_mass_ * n.dot(sphere));
    }
  }

  // Solves the LCP from nu (u its response, w its residual) by (2.18); on return nu, u and w
  // are the solution's. Returns the pivots used, or -1 when it did not converge.
  int solve(const double* q, double* nu, double* w) {
    const double* p = work_.previous_multiplier.data();
    const double* W = work_.delassus.data();
    double* q_k = work_.splitting.data();
    double* next = q_k + m_;
    double* delta = next + m_;
    int* guess = work_.guess.data();
    const double cg_tolerance = opt_.integrator.cg_tolerance;
    int pivots = 0;
    bool refreshed = false;
    double previous_step = INFINITY;
    for (int k = 1;; ++k) {
      // (2.18): nu_k+1 solves the LCP of W~ with w_k + W~ (nu_k+1 - nu_k), pivoting from nu_k's set.
      for (int a = 0; a < m_; ++a) {
        double s = w[a];
        for (int b = 0; b < m_; ++b) s -= W[a * m_ + b] * nu[b];
        q_k[a] = s;
        guess[a] = std::isfinite(w[a]) && (nu[a] > 0.0 || w[a] < 0.0);
      }
      const int iterations = solve_signorini_lcp(m_, W, q_k, next, opt_.contact.tolerance, opt_.contact.max_iterations, work_, guess);
      pivots += std::max(iterations, 0);
      double step2 = 0.0, nu2 = 0.0, p2 = 0.0;
      for (int a = 0; a < m_; ++a) {
        delta[a] = next[a] - nu[a];
        step2 += delta[a] * delta[a];
        nu2 += next[a] * next[a];
        p2 += p[a] * p[a];
      }
      // The response to the contact forces to cg_tolerance, as the free motion's CG solves its load.
      const double scale = std::sqrt(std::max(nu2, p2));
      add_response(delta, cg_tolerance * scale);
      std::copy(next, next + m_, nu);
      residual(q, nu, w);
      ++state_.out.contact_splitting_iterations;
      const double step = std::sqrt(step2);
      if (iterations >= 0 && step <= kSplittingTolerance * cg_tolerance * scale) return pivots;
      if (k >= kMaxSplitting) return -1;
      if (!refreshed && k >= kJudgeAfter && (iterations < 0 || step > kSlowContraction * previous_step)) {
        load_columns(true, cg_tolerance);  // W~ too far from W: W itself
        refreshed = true;
      }
      previous_step = step;
    }
  }

 private:
  double tool_part(int a, const Vec3& n_b) const {
    return dt2_ * inv_sphere_mass_ * work_.normal.col(a).dot(axes_.cwiseProduct(n_b));
  }

  void count_solve(int iterations) {
    ++state_.out.contact_cg_solves;
    state_.out.contact_cg_iterations += iterations >= 0 ? iterations : opt_.integrator.cg_max_iterations;
  }

  // u += A^-1 J^T delta, to a residual of `residual_norm` (nothing to do when |delta| is below it).
  void add_response(const double* delta, double residual_norm) {
    double norm2 = 0.0;
    for (int a = 0; a < m_; ++a) norm2 += delta[a] * delta[a];
    if (std::sqrt(norm2) <= residual_norm) return;
    work_.rhs.setZero();
    for (int a = 0; a < m_; ++a) work_.rhs.col(state_.out.contact_candidate[a]) = delta[a] * work_.normal.col(a);
    count_solve(A_.solve(work_.rhs, work_.dv, residual_norm));
    work_.contact_response += work_.dv;
  }

  // A free slot for particle i, the cache grown (its entries moved) when there is none.
  int allocate_slot(int i) {
    ComplianceCache& c = work_.compliance;
    int s = static_cast<int>(std::find(c.particle.begin(), c.particle.end(), -1) - c.particle.begin());
    if (s == c.capacity) {
      const int old = c.capacity, cap = std::max(64, 2 * old);
      std::vector<double> entry(static_cast<size_t>(cap) * cap, 0.0);
      for (int r = 0; r < old; ++r)
        std::copy(c.entry.begin() + static_cast<ptrdiff_t>(r) * old, c.entry.begin() + static_cast<ptrdiff_t>(r + 1) * old,
                  entry.begin() + static_cast<ptrdiff_t>(r) * cap);
      c.entry.swap(entry);
      c.particle.resize(cap, -1);
      c.last_used.resize(cap, 0);
      c.direction.conservativeResize(3, cap);
      c.capacity = cap;
    }
    c.particle[s] = i;
    c.slot[i] = s;
    return s;
  }

  const Model& model_;
  const Options& opt_;
  State& state_;
  Workspace& work_;
  LinearResponse& A_;
  const int m_;
  const double dt2_, inv_sphere_mass_;
  const Vec3 axes_;
};

}  // namespace

int gather_contact_candidates(const Model& model, State& state) {
  Workspace& work = state.work;
  const int n = model.particle_count;
  const double R = model.indenter_radius;
  const Vec3 c = state.indenter_center;
  std::vector<int>& candidate = state.out.contact_candidate;
  candidate.clear();
  work.gap.clear();
  work.previous_multiplier.clear();
  auto add_candidate = [&](int i) {
    const Vec3 r = state.position.col(i) - c;
    const double dist = r.norm();
    const int a = static_cast<int>(candidate.size());
    candidate.push_back(i);
    work.gap.push_back(dist - R);
    work.normal.col(a) = dist > 0 ? Vec3(r / dist) : Vec3(0, 0, -1);
    work.previous_multiplier.push_back(0.0);
    work.previous_force.col(a).setZero();
    work.candidate_slot[i] = a;
  };
  for (int i = 0; i < n; ++i) {
    if (model.inverse_mass[i] == 0.0) continue;
    if ((state.position.col(i) - c).squaredNorm() < R * R) add_candidate(i);
  }
  for (size_t k = 0; k < state.contact_index.size(); ++k) {
    const int i = state.contact_index[k];
    if (work.candidate_slot[i] < 0) add_candidate(i);
    const int a = work.candidate_slot[i];
    const Vec3 f = state.contact_force.col(static_cast<Eigen::Index>(k));
    work.previous_force.col(a) = f;
    work.previous_multiplier[a] = f.dot(work.normal.col(a));  // along this step's normal
  }
  const int m = static_cast<int>(candidate.size());
  for (int a = 0; a < m; ++a) work.candidate_slot[candidate[a]] = -1;
  state.contact_index.clear();
  state.contact_normal_force.clear();
  state.indenter_contact_force.setZero();
  state.out.contact_iterations = 0;
  state.out.contact_max_penetration = 0.0;
  state.out.contact_columns = state.out.contact_splitting_iterations = 0;
  state.out.contact_cg_solves = state.out.contact_cg_iterations = 0;
  return m;
}

StepStatus solve_contact(const Model& model, const Options& opt, State& state, LinearResponse* coupled) {
  Workspace& work = state.work;
  const double dt = opt.integrator.dt;
  const double tolerance = opt.contact.tolerance;
  const int max_iterations = opt.contact.max_iterations;
  const std::vector<int>& candidate = state.out.contact_candidate;
  const int m = gather_contact_candidates(model, state);
  if (m == 0) return StepStatus::ok;

  // Delassus operator W = dt^2 J M^-1 J^T, the sphere's translations included:
  // W_ab = dt^2 [ n_a . (response of particle a to a unit force n_b on b) + n_a . P n_b / M ],
  // P = diag(tool_axes): the axes the tool moves along (a guided axis has infinite mass) (2.4).
  // Explicit integrators: W = D + U U^T, D_aa = dt^2 / m_a, U_a = dt (P / M)^1/2 n_a, never
  // formed (LumpedDelassus). Implicit Euler: the body's response is A^-1, W~ of (2.17) in
  // work.delassus, the exact W in the splitting.
  const double dt2 = dt * dt;
  const double inv_sphere_mass = 1.0 / tool_effective_mass(opt);  // with a coupling: implicit in it
  const Vec3 axes = tool_axes(opt);
  std::optional<CoupledContact> implicit;
  std::optional<LumpedDelassus> lumped;
  if (coupled) {
    work.delassus.resize(static_cast<size_t>(m) * m);
    implicit.emplace(model, opt, state, *coupled);
    implicit->load_columns(false, std::max(kColumnTolerance, opt.integrator.cg_tolerance));
  } else {
    work.delassus_diagonal.resize(m);
    work.delassus_factor.resize(3 * static_cast<size_t>(m));
    const Vec3 scale = dt * (inv_sphere_mass * axes).cwiseSqrt();
    for (int a = 0; a < m; ++a) {
      work.delassus_diagonal[a] = dt2 * model.inverse_mass[candidate[a]];
      const Vec3 u = scale.cwiseProduct(work.normal.col(a));
      for (int j = 0; j < 3; ++j) work.delassus_factor[3 * a + j] = u[j];
    }
    lumped.emplace(work.delassus_diagonal.data(), work.delassus_factor.data());
  }
  // out = W x (the explicit integrators' W; implicit Euler's gaps come from its residual).
  auto times_W = [&](const double* x, double* out) { lumped->apply(m, x, out); };

  // Replaces the previous contact forces (held over the free motion) by `total`:
  // particles += gain M^-1 (total_a n_a - f_prev,a) (implicit Euler: gain A^-1 J^T (total - p),
  // work.contact_response), the tool likewise with the reactions. Returns the contact force
  // of `total` on the tool.
  auto apply = [&](const double* total, double gain, Points& particles, Vec3& indenter) {
    Vec3 sphere_force = Vec3::Zero(), sphere_previous = Vec3::Zero();
    for (int a = 0; a < m; ++a) {
      const int i = candidate[a];
      const Vec3 f = total[a] * work.normal.col(a);
      if (!coupled) particles.col(i) += (gain * model.inverse_mass[i]) * (f - work.previous_force.col(a));
      sphere_force -= f;
      sphere_previous -= work.previous_force.col(a);
    }
    if (coupled) particles += gain * work.contact_response;
    indenter += gain * inv_sphere_mass * axes.cwiseProduct(sphere_force - sphere_previous);
    return sphere_force;
  };
  // The LCPs are posed in the total multipliers: g' = (g - W p) + W lambda, p the previous ones.
  const double* previous = work.previous_multiplier.data();
  work.delassus_product.resize(m);
  double* W_times = work.delassus_product.data();
  auto shift_by_previous = [&](double* g) {
    times_W(previous, W_times);
    for (int a = 0; a < m; ++a) g[a] -= W_times[a];
  };
  // Pivoting starts from the previous step's contact set and the particles that penetrate
  // (in a running simulation the set changes by a few particles a step).
  if (work.guess.size() < static_cast<size_t>(m)) work.guess.resize(m);
  int* guess = work.guess.data();

  // 1. Position projection.
  work.multiplier.resize(m);
  double* lambda = work.multiplier.data();
  int iterations = 0;
  if (coupled) {
    // From lambda = p, where u = 0 and w = g; the exact gaps at the solution end in work.gap.
    std::copy(previous, previous + m, lambda);
    work.contact_response.setZero();
    double* w = work.splitting.data() + 3 * m;
    std::copy(work.gap.begin(), work.gap.end(), w);
    iterations = implicit->solve(work.gap.data(), lambda, w);
    std::copy(w, w + m, work.gap.begin());
  } else {
    shift_by_previous(work.gap.data());
    for (int a = 0; a < m; ++a) guess[a] = previous[a] > 0.0 || work.gap[a] < 0.0;
    iterations = solve_signorini_lcp_lumped(m, work.delassus_diagonal.data(), work.delassus_factor.data(), work.gap.data(), lambda,
                                            tolerance, max_iterations, work, guess);
  }
  bool converged = iterations >= 0;
  state.out.contact_iterations = std::max(iterations, 0);
  apply(lambda, dt2, state.position, state.indenter_center);

  // Gaps after the projection: who is touching, and the penetration left.
  if (!coupled) {
    times_W(lambda, W_times);
    for (int a = 0; a < m; ++a) work.gap[a] += W_times[a];
  }
  for (int a = 0; a < m; ++a) state.out.contact_max_penetration = std::max(state.out.contact_max_penetration, -work.gap[a]);

  // 2. Velocity projection on the touching particles; the others are given an
  // infinite separating velocity so that the LCP leaves them at zero force.
  // u_a = n_a . (v_i - v_tool), posed as u dt with W (= W_v dt).
  for (int a = 0; a < m; ++a) {
    const bool touching = work.gap[a] <= 10 * tolerance;
    const Vec3 v_rel = state.velocity.col(candidate[a]) - state.indenter_velocity;
    work.gap[a] = work.normal.col(a).dot(v_rel) * dt;
    if (!touching) work.gap[a] = INFINITY;
  }
  double* mu = lambda;  // lambda has been applied: reuse its buffer
  if (coupled) {
    // From mu = lambda, whose response u is at hand.
    double* w = work.splitting.data() + 3 * m;
    implicit->residual(work.gap.data(), mu, w);
    iterations = implicit->solve(work.gap.data(), mu, w);
  } else {
    shift_by_previous(work.gap.data());
    for (int a = 0; a < m; ++a) guess[a] = mu[a] > 0.0;  // the position projection's set
    iterations = solve_signorini_lcp_lumped(m, work.delassus_diagonal.data(), work.delassus_factor.data(), work.gap.data(), mu,
                                            tolerance, max_iterations, work, guess);
  }
  converged = converged && iterations >= 0;
  state.out.contact_iterations += std::max(iterations, 0);
  // mu is the contact force of the step (momentum exchanged / dt): the state reports it.
  state.indenter_contact_force = apply(mu, dt, state.velocity, state.indenter_velocity);
  for (int a = 0; a < m; ++a) {
    if (mu[a] <= 0.0) continue;
    const int slot = static_cast<int>(state.contact_index.size());
    state.contact_index.push_back(candidate[a]);
    state.contact_normal_force.push_back(mu[a]);
    state.contact_force.col(slot) = mu[a] * work.normal.col(a);
  }
  return converged ? StepStatus::ok : StepStatus::contact_not_converged;
}

}  // namespace palpate
