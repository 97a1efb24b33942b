#include "core/time_step.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "core/mls_forces.h"
#include "core/thread_pool.h"

namespace palpate {

double stability_constant(SolidKind solid, IntegratorType integrator, DistributionType distribution) {
  // c = dt_max c_p / dx_min measured at the Hertz load (palpate-stable-dt / palpate-stress,
  // bisection to 1-2 %, damping 10 1/s; docs/stability.md):
  //                           uniform 18^3   graded 21^3 (implicit: 11^3)
  //   MLS      RK4               1.51          2.07
  //   MLS      sympl. Euler      0.985         1.23
  //   MLS      implicit Euler    1.07          1.05
  //   hex FEM  RK4               1.48          1.58
  //   hex FEM  sympl. Euler      0.926         1.08
  //   hex FEM  implicit Euler    1.08          5.23
  // Implicit Euler is limited too: the indenter's motion is coupled to the body through
  // the contact solve, not inside the implicit system. Clouds other than these two
  // (jittered, node files, meshes) get the smaller constant.
  static constexpr double c[2][3][2] = {
      {{1.51, 2.07}, {0.985, 1.23}, {1.07, 1.05}},   // MLS: rk4, symplectic Euler, implicit Euler
      {{1.48, 1.58}, {0.926, 1.08}, {1.08, 5.23}}};  // hex FEM
  const auto& pair = c[solid == SolidKind::mls ? 0 : 1][static_cast<int>(integrator)];
  if (distribution == DistributionType::grid) return pair[0];
  if (distribution == DistributionType::graded_grid) return pair[1];
  return std::min(pair[0], pair[1]);
}

namespace {

// c_p with the volume term: sqrt((lambda + 2 mu + k_v) / rho), m/s, of the fastest material
// present (a heterogeneous body: the max over the particles' own parameters, so a stiff
// inclusion shrinks the stable dt).
double envelope_wave_speed(const Model& model) {
  double c2 = (model.lame_lambda + 2 * model.lame_mu + model.volume_stiffness) / model.density;
  if (model.particle_lambda.size() == static_cast<size_t>(model.particle_count) &&
      model.particle_mu.size() == model.particle_lambda.size() &&
      model.particle_density.size() == model.particle_lambda.size()) {
    c2 = 0.0;
    for (int i = 0; i < model.particle_count; ++i)
      c2 = std::max(c2, (model.particle_lambda[i] + 2 * model.particle_mu[i] + model.volume_stiffness) /
                            model.particle_density[i]);
  }
  return std::sqrt(c2);
}

double envelope_constant(const Model& model, IntegratorType integrator) {
  return stability_constant(model.solid, integrator, model.distribution);
}

// The largest eigenvalue of the Lanczos tridiagonal matrix (diagonal alpha, off-diagonal
// beta[0 .. m-2]) and its residual bound beta[m-1] |y_m|: ||A v - theta v|| of its Ritz vector.
struct RitzPair {
  double value, residual;
};
RitzPair largest_ritz(const std::vector<double>& alpha, const std::vector<double>& beta) {
  const int m = static_cast<int>(alpha.size());
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(m, m);
  for (int j = 0; j < m; ++j) {
    T(j, j) = alpha[j];
    if (j + 1 < m) T(j, j + 1) = T(j + 1, j) = beta[j];
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(T);
  return {eig.eigenvalues()[m - 1], beta[m - 1] * std::abs(eig.eigenvectors()(m - 1, m - 1))};
}

constexpr int kMinSteps = 20;         // Lanczos steps before convergence is looked at
constexpr double kConverged = 1e-6;  // residual bound / Ritz value that ends the iteration

}  // namespace

double stable_time_step(const Model& model, IntegratorType integrator) {
  return envelope_constant(model, integrator) * model.min_spacing / envelope_wave_speed(model);
}

double spectral_time_step(const Model& model, IntegratorType integrator) {
  if (model.solid != SolidKind::mls || integrator == IntegratorType::implicit_euler) return 0.0;
  const int n = model.particle_count;
  // A = M^-1/2 K M^-1/2 on the free particles (K = -df/dx at rest).
  std::vector<double> scale(n);
  int free_count = 0;
  for (int i = 0; i < n; ++i) {
    scale[i] = model.fixed[i] ? 0.0 : 1.0 / std::sqrt(model.mass[i]);
    free_count += !model.fixed[i];
  }
  if (free_count == 0) return 0.0;
  std::vector<double> tangent_F, tangent_law_factor;
  mls_linearize(model, model.rest_position, tangent_F, tangent_law_factor);
  Points dx(3, n), df(3, n);
  auto apply = [&](const Points& v, Points& out) {
    for (int i = 0; i < n; ++i) dx.col(i) = scale[i] * v.col(i);
    mls_force_differential(model, tangent_F, tangent_law_factor, dx, df);
    for (int i = 0; i < n; ++i) out.col(i) = -scale[i] * df.col(i);
  };
  const int steps = std::min(60, 3 * free_count);
  std::vector<Points> basis;
  basis.reserve(steps + 1);
  // A fixed, seeded start (the result must not depend on the run).
  std::mt19937_64 rng(20261206);
  Points q(3, n);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) q(c, i) = scale[i] > 0 ? static_cast<double>(rng() >> 11) * 0x1.0p-53 - 0.5 : 0.0;
  q /= q.norm();
  basis.push_back(q);
  std::vector<double> alpha, beta;
  Points w(3, n);
  for (int j = 0; j < steps; ++j) {
    apply(basis[j], w);
    alpha.push_back((w.array() * basis[j].array()).sum());
    for (const Points& b : basis) w -= (w.array() * b.array()).sum() * b;  // full reorthogonalisation
    for (const Points& b : basis) w -= (w.array() * b.array()).sum() * b;  // twice is enough
    const double norm = w.norm();
    beta.push_back(norm);
    if (norm <= 1e-12 * std::abs(alpha.back())) break;
    // Converged: from 20 steps on, every 5, the largest Ritz value's residual bound within
    // 1e-6 of it (on the refined block it is 2e-5 at 20 steps and 4e-8 at 30; the 60 steps
    // spent otherwise were half of a refocus's model build).
    if (j + 1 >= kMinSteps && (j + 1) % 5 == 0) {
      const RitzPair top = largest_ritz(alpha, beta);
      if (top.residual <= kConverged * top.value) break;
    }
    basis.push_back(w / norm);
  }
  const RitzPair top = largest_ritz(alpha, beta);
  const double ritz = top.value, residual = top.residual;
  const double omega = std::sqrt(std::max(ritz + residual, 1e-300));
  return (integrator == IntegratorType::rk4 ? 2.785 : 2.0) / omega;
}

void check_options(const Model& model, const Options& opt) {
  const IntegratorSpec& in = opt.integrator;
  if (in.threads < 1 || in.threads > kMaxThreads)
    throw SceneError(model.source, "/integrator/threads",
                     std::to_string(in.threads) + " threads (1 ... " + std::to_string(kMaxThreads) + ")");
  const double dt_max = stable_time_step(model, in.type);
  if (in.allow_unstable_dt || in.dt <= dt_max) return;
  if (model.spectral_time_step > 0 && in.dt <= kSpectralSafety * model.spectral_time_step) return;
  char text[768];
  std::snprintf(text, sizeof text,
                "%g s is outside the measured stable envelope of %s with the %s model: dt <= c dx_min / c_p = "
                "%.3g x %.4g m / %.4g m/s = %.4g s (docs/stability.md). Use a smaller dt, or set "
                "integrator.allow_unstable_dt to true to run anyway",
                in.dt, to_string(in.type), to_string(model.solid), envelope_constant(model, in.type), model.min_spacing,
                envelope_wave_speed(model), dt_max);
  std::string message = text;
  if (model.spectral_time_step > 0) {
    std::snprintf(text, sizeof text, "; nor within %g of the model's spectral estimate 2 / omega_max = %.4g s",
                  kSpectralSafety, model.spectral_time_step);
    message.insert(message.find(" (docs/stability.md)"), text);
  }
  throw SceneError(model.source, "/integrator/dt", message);
}

}  // namespace palpate
