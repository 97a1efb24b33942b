// palpate-stress, study 4: zero-energy modes. The energy and force ratios of an
// enveloped checkerboard against the smooth field (MLS with each hourglass
// coefficient, the hex FEM), then the checkerboard and velocity noise run with
// and without hourglass control and damping.
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "analysis/diagnostics.h"
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/solid.h"
#include "core/state.h"
#include "core/step.h"
#include "tools/stress/studies.h"

namespace palpate::stress {

namespace {

// Least-squares slope of log(y) against t.
double log_slope(const std::vector<double>& t, const std::vector<double>& y) {
  double st = 0, sy = 0, stt = 0, sty = 0;
  int n = 0;
  for (size_t k = 0; k < t.size(); ++k) {
    if (!(y[k] > 0)) continue;
    const double ly = std::log(y[k]);
    st += t[k];
    sy += ly;
    stt += t[k] * t[k];
    sty += t[k] * ly;
    ++n;
  }
  if (n < 2) return NAN;
  return (n * sty - st * sy) / (n * stt - st * st);
}

// The checkerboard s_i A phi(X_i) e with the smooth envelope phi = prod_a sin(pi (X_a - min_a) / L_a)
// (zero on every face) and e = (1,1,1)/sqrt3 on the free particles; sign = +1 everywhere gives the
// smooth field A phi e itself.
Points enveloped(const Model& m, const std::vector<double>& sign, double A) {
  const Points& X = m.rest_position;
  const Vec3 lo = X.rowwise().minCoeff(), hi = X.rowwise().maxCoeff();
  const Vec3 e = Vec3::Ones().normalized();
  Points u = Points::Zero(3, m.particle_count);
  for (int i = 0; i < m.particle_count; ++i) {
    if (m.inverse_mass[i] == 0.0) continue;
    double phi = 1;
    for (int a = 0; a < 3; ++a) phi *= std::sin(M_PI * (X(a, i) - lo[a]) / (hi[a] - lo[a]));
    u.col(i) = sign[i] * A * phi * e;
  }
  return u;
}

}  // namespace

json zero_energy_study(const StressOptions& stress, json& meta, json& series, json& ratios) {
  const double duration = stress.mode == Mode::full ? 3.0 : stress.mode == Mode::quick ? 1.5 : 0.1;
  const double window = 0.1;  // s: the envelope of |a| is the max over each window
  meta["zero_energy_protocol"] =
      "MLS (and, for the energy ratio, the hex FEM on the same lattice). Energy ratio: strain energy of the enveloped "
      "checkerboard u_i = s_i A phi(X_i) e over that of the smooth field A phi(X_i) e, s_i = (-1)^(a+b+c) of lattice node "
      "(a,b,c), phi = prod sin(pi (X - min) / L) over the axes, e = (1,1,1)/sqrt3, A = 1e-3 dx_min (linear range); "
      "force ratio: the same for the generalised force -f . u / A. A discretisation that sees the checkerboard's strain "
      "gives a ratio >> 1 (the hex FEM: its value on the lattice); 1 is a zero-energy mode (the checkerboard costs only "
      "its envelope). Dynamics: symplectic Euler at 1 ms, no force command, " + std::to_string(duration) +
      " s from (checkerboard) u = the enveloped checkerboard with A = 1 % of dx_min at rest or (noise) u = 0, "
      "v_i ~ N(0, (0.01 m/s)^2) per component (seed 7); a(t) = |sum_i s_i u_i| / free particles; rate = least-squares "
      "slope of log(max |a| over 0.1 s windows) against time (1/s; < 0 decays; noise: over the second half); "
      "ratio_end = a(T)/a(0) (checkerboard) or a(T) / a_free(T), a_free = a'(0) (1 - exp(-c T)) / c (a'(0) T when c = 0): "
      "the motion of a mode without any stiffness.";
  std::vector<Cloud> cl = clouds(stress.mode);
  if (stress.mode == Mode::smoke) cl.resize(1);
  // Energy and force ratios (cheap: a few energy evaluations).
  for (const Cloud& cloud : cl) {
    for (const double hg : {-1.0, 0.0, 0.02, 0.1, 0.5}) {  // -1: the hex FEM
      const Scene scene = hg < 0 ? load(stress, cloud.fem_scene, cloud.per_edge)
                                 : load(stress, cloud.mls_scene, cloud.per_edge, {{"mls.hourglass", std::to_string(hg)}});
      const Model model = build_model(scene);
      const std::vector<double> sign = checkerboard_sign(model), ones(model.particle_count, 1.0);
      const double A = 1e-3 * model.min_spacing;
      const Points uc = enveloped(model, sign, A), us = enveloped(model, ones, A);
      const Points xc = model.rest_position + uc, xs = model.rest_position + us;
      const double Uc = elastic_energy(model, xc), Us = elastic_energy(model, xs);
      Points f(3, model.particle_count);
      elastic_forces(model, xc, f);
      const double Qc = -(f.array() * uc.array()).sum() / A;
      elastic_forces(model, xs, f);
      const double Qs = -(f.array() * us.array()).sum() / A;
      progress("zero energy: %s %s, hourglass %s: energy ratio %.4g, force ratio %.4g", model_label(model),
               cloud_label(model, cloud.name).c_str(), hg < 0 ? "-" : std::to_string(hg).c_str(), Uc / Us, Qc / Qs);
      ratios.push_back({{"model", model_label(model)}, {"cloud", cloud_label(model, cloud.name)},
                        {"particles", model.particle_count}, {"hourglass", hg < 0 ? json(nullptr) : json(hg)},
                        {"energy_checkerboard_j", Uc}, {"energy_smooth_j", Us}, {"energy_ratio", Uc / Us},
                        {"force_ratio", Qc / Qs}});
    }
  }
  // Dynamics on the uniform cloud (the graded cloud's hourglass runs take minutes).
  json rows = json::array();
  const Cloud& cloud = cl[0];
  for (const double hg : {0.0, 0.1}) {
    const Scene scene = load(stress, cloud.mls_scene, cloud.per_edge, {{"mls.hourglass", std::to_string(hg)}});
    const Model model = build_model(scene);
    const std::vector<double> sign = checkerboard_sign(model);
    int free_count = 0;
    for (int i = 0; i < model.particle_count; ++i) free_count += model.inverse_mass[i] != 0.0;
    for (const double damping : {0.0, 10.0}) {
      Options opt = options_of(scene);
      opt.integrator.type = IntegratorType::symplectic_euler;
      opt.integrator.dt = 1e-3;
      opt.integrator.damping = damping;
      for (const std::string perturbation : {"checkerboard", "noise"}) {
        const auto t0 = Clock::now();
        State s = make_state(model, opt);
        s.force_command.setZero();
        if (perturbation == "checkerboard") {
          s.position += enveloped(model, sign, 0.01 * model.min_spacing);
        } else {
          std::mt19937_64 rng(7);
          std::normal_distribution<double> noise(0.0, 0.01);
          for (int i = 0; i < model.particle_count; ++i)
            if (model.inverse_mass[i] != 0.0) s.velocity.col(i) = Vec3(noise(rng), noise(rng), noise(rng));
        }
        Vec3 vc = Vec3::Zero();  // a'(0): the checkerboard component of the initial velocity
        for (int i = 0; i < model.particle_count; ++i)
          if (model.inverse_mass[i] != 0.0) vc += sign[i] * s.velocity.col(i);
        const double a_dot0 = vc.norm() / free_count;
        const double a0 = checkerboard_amplitude(model, sign, s.position);
        std::vector<double> wt, wa;
        double wmax = 0;
        const long steps = std::lround(duration / 1e-3), per_window = std::lround(window / 1e-3);
        bool finite = true;
        json ts = json::array();
        for (long k = 1; k <= steps; ++k) {
          if (step(model, opt, s) == StepStatus::non_finite) {
            finite = false;
            break;
          }
          const double a = checkerboard_amplitude(model, sign, s.position);
          wmax = std::max(wmax, a);
          if (k % 10 == 0) ts.push_back({k * 1e-3, a});
          if (k % per_window == 0) {
            wt.push_back((k - 0.5 * per_window) * 1e-3);
            wa.push_back(wmax);
            wmax = 0;
          }
        }
        const double T = steps * 1e-3;
        const double aT = finite ? checkerboard_amplitude(model, sign, s.position) : NAN;
        const size_t skip = perturbation == "noise" ? wt.size() / 2 : 0;
        const double rate = log_slope(std::vector<double>(wt.begin() + skip, wt.end()),
                                      std::vector<double>(wa.begin() + skip, wa.end()));
        const double a_free = damping > 0 ? a_dot0 * (1 - std::exp(-damping * T)) / damping : a_dot0 * T;
        const double ratio_end = perturbation == "noise" ? aT / a_free : aT / a0;
        progress("zero energy: %s, hourglass %g, damping %g, %s: a(0) = %.3g m, a'(0) = %.3g m/s, a(T) = %.3g m, "
                 "rate %.3g /s, ratio %.3g (%.1f s)",
                 cloud_label(model, cloud.name).c_str(), hg, damping, perturbation.c_str(), a0, a_dot0, aT, rate,
                 ratio_end, seconds_since(t0));
        json row;
        row["cloud"] = cloud_label(model, cloud.name);
        row["particles"] = model.particle_count;
        row["hourglass"] = hg;
        row["damping"] = damping;
        row["perturbation"] = perturbation;
        row["duration_s"] = T;
        row["finite"] = finite;
        row["a0_m"] = a0;
        row["a_dot0_m_s"] = a_dot0;
        row["a_end_m"] = num(aT);
        row["rate_per_s"] = num(rate);
        row["ratio_end"] = num(ratio_end);
        row["wall_s"] = seconds_since(t0);
        rows.push_back(row);
        series.push_back({{"cloud", row["cloud"]}, {"hourglass", hg}, {"damping", damping},
                          {"perturbation", perturbation}, {"a", ts}});
      }
    }
  }
  return rows;
}

}  // namespace palpate::stress
