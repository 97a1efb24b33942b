#include "core/mls_forces.h"

#include <Eigen/Geometry>
#include <cmath>

namespace palpate {

namespace {

// Green strain E = 1/2 (F^T F - I) and the St Venant-Kirchhoff second Piola
// stress S = lambda tr(E) I + 2 mu E, returning the energy density 1/2 E:S.
inline double stvk_stress(const Mat3& F, double lambda, double mu, Mat3& S) {
  const Mat3 E = 0.5 * (F.transpose() * F - Mat3::Identity());
  S = (2 * mu) * E;
  S.diagonal().array() += lambda * E.trace();
  return 0.5 * (E.array() * S.array()).sum();
}

// Cofactor matrix cof(F) = det(F) F^-T: its columns are the columns of F crossed pairwise
// (d det F / dF).
inline Mat3 cofactor(const Mat3& F) {
  Mat3 C;
  C.col(0) = F.col(1).cross(F.col(2));
  C.col(1) = F.col(2).cross(F.col(0));
  C.col(2) = F.col(0).cross(F.col(1));
  return C;
}

inline Mat3 gradient_at(const Model& m, const double* x, int i) {
  const double* D = m.gradient_weight.data();
  const int* idx = m.neighbor_index.data();
  Mat3 F = Eigen::Map<const Mat3>(&m.rest_correction[9 * static_cast<size_t>(i)]);
  const double xi0 = x[3 * i], xi1 = x[3 * i + 1], xi2 = x[3 * i + 2];
  for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
    const double* xj = x + 3 * idx[a];
    const double* d = D + 3 * a;
    const double u0 = xj[0] - xi0, u1 = xj[1] - xi1, u2 = xj[2] - xi2;
    F(0, 0) += u0 * d[0]; F(0, 1) += u0 * d[1]; F(0, 2) += u0 * d[2];
    F(1, 0) += u1 * d[0]; F(1, 1) += u1 * d[1]; F(1, 2) += u1 * d[2];
    F(2, 0) += u2 * d[0]; F(2, 1) += u2 * d[1]; F(2, 2) += u2 * d[2];
  }
  return F;
}

// Hourglass control: residuals r_ij = x_ij - F X_ij of the MLS fit, energy
// 1/2 sum_j kappa w_ij |r_ij|^2 (zero for every affine motion). Its gradient has a
// direct part on each neighbour and a part through F, G = sum_j kappa w_ij r_ij X_ij^T,
// which the caller folds into the stress term (f_j = -(v_i P - G) d_j).
// With f != nullptr the direct forces -kappa w_ij r_ij (and their reaction on i) are
// added to f. Works for positions (x, F) and for differentials (dx, dF) alike.
inline double hourglass_forces(const Model& m, const double* x, int i, const Mat3& F, Mat3& G, double* f) {
  const int* idx = m.neighbor_index.data();
  G.setZero();
  double energy = 0;
  const Vec3 xi(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
  Vec3 fi = Vec3::Zero();
  for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
    const Vec3 X_ij = m.neighbor_rest_offset.col(a);
    const Vec3 r = Eigen::Map<const Vec3>(x + 3 * idx[a]) - xi - F * X_ij;
    const double kw = m.hourglass_weight[a];
    energy += 0.5 * kw * r.squaredNorm();
    G += kw * r * X_ij.transpose();
    if (f) {
      Eigen::Map<Vec3>(f + 3 * idx[a]) -= kw * r;
      fi += kw * r;
    }
  }
  if (f) Eigen::Map<Vec3>(f + 3 * i) += fi;
  return energy;
}

// First Piola stress P of particle i (elastic + volume term) and its energy density.
inline double piola_stress(const Model& m, const Mat3& F, Mat3& P, Mat3* S_out = nullptr) {
  Mat3 S;
  double psi = stvk_stress(F, m.lame_lambda, m.lame_mu, S);
  P = F * S;
  if (m.volume_stiffness > 0) {  // U = 1/2 k_v (det F - 1)^2, P += k_v (J - 1) cof(F)
    const Mat3 C = cofactor(F);
    const double J = F.col(0).dot(C.col(0));
    psi += 0.5 * m.volume_stiffness * (J - 1) * (J - 1);
    P += m.volume_stiffness * (J - 1) * C;
  }
  if (S_out) *S_out = S;
  return psi;
}

}  // namespace

Mat3 deformation_gradient(const Model& model, const Points& x, int i) { return gradient_at(model, x.data(), i); }

double first_piola_stress(const Model& model, const Mat3& F, Mat3& P) { return piola_stress(model, F, P); }

void internal_forces(const Model& m, const Points& x_points, Points& f_points) {
  const int n = m.particle_count;
  const double* x = x_points.data();
  double* f = f_points.data();
  const double* D = m.gradient_weight.data();
  const int* idx = m.neighbor_index.data();
  const bool hourglass = !m.hourglass_weight.empty();
  f_points.setZero();
  for (int i = 0; i < n; ++i) {
    const Mat3 F = gradient_at(m, x, i);
    Mat3 P;
    piola_stress(m, F, P);
    // Forces: f_j = -v_i P d_j on every neighbour, f_i = -v_i P d_i = v_i P sum_j d_j.
    Mat3 vP = m.volume[i] * P;
    if (hourglass) {
      Mat3 G;
      hourglass_forces(m, x, i, F, G, f);
      vP -= G;
    }
    double fi0 = 0, fi1 = 0, fi2 = 0;
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const double* d = D + 3 * a;
      double* fj = f + 3 * idx[a];
      const double g0 = vP(0, 0) * d[0] + vP(0, 1) * d[1] + vP(0, 2) * d[2];
      const double g1 = vP(1, 0) * d[0] + vP(1, 1) * d[1] + vP(1, 2) * d[2];
      const double g2 = vP(2, 0) * d[0] + vP(2, 1) * d[1] + vP(2, 2) * d[2];
      fj[0] -= g0; fj[1] -= g1; fj[2] -= g2;
      fi0 += g0; fi1 += g1; fi2 += g2;
    }
    f[3 * i] += fi0;
    f[3 * i + 1] += fi1;
    f[3 * i + 2] += fi2;
  }
}

double strain_energy(const Model& m, const Points& x) {
  double U = 0;
  for (int i = 0; i < m.particle_count; ++i) {
    const Mat3 F = gradient_at(m, x.data(), i);
    Mat3 P;
    U += m.volume[i] * piola_stress(m, F, P);
    if (!m.hourglass_weight.empty()) {
      Mat3 G;
      U += hourglass_forces(m, x.data(), i, F, G, nullptr);
    }
  }
  return U;
}

void linearize_forces(const Model& m, const Points& x, std::vector<double>& cached_F,
                      std::vector<double>& cached_S) {
  cached_F.resize(9 * static_cast<size_t>(m.particle_count));
  cached_S.resize(9 * static_cast<size_t>(m.particle_count));
  for (int i = 0; i < m.particle_count; ++i) {
    const Mat3 F = gradient_at(m, x.data(), i);
    Mat3 S;
    stvk_stress(F, m.lame_lambda, m.lame_mu, S);
    Eigen::Map<Mat3> F_out(&cached_F[9 * static_cast<size_t>(i)]), S_out(&cached_S[9 * static_cast<size_t>(i)]);
    F_out = F;
    S_out = S;
  }
}

void force_differential(const Model& m, const std::vector<double>& cached_F,
                        const std::vector<double>& cached_S, const Points& dx_points, Points& df_points) {
  const double* dx = dx_points.data();
  double* df = df_points.data();
  const double* D = m.gradient_weight.data();
  const int* idx = m.neighbor_index.data();
  df_points.setZero();
  for (int i = 0; i < m.particle_count; ++i) {
    const Eigen::Map<const Mat3> F(&cached_F[9 * static_cast<size_t>(i)]);
    const Eigen::Map<const Mat3> S(&cached_S[9 * static_cast<size_t>(i)]);
    // dF = sum_j (dx_j - dx_i) d_j^T (the rest correction is constant).
    Mat3 dF = Mat3::Zero();
    const Vec3 dxi = Eigen::Map<const Vec3>(dx + 3 * i);
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a)
      dF += (Eigen::Map<const Vec3>(dx + 3 * idx[a]) - dxi) * Eigen::Map<const Vec3>(D + 3 * a).transpose();
    // dE = sym(F^T dF), dS = lambda tr(dE) I + 2 mu dE, dP = dF S + F dS.
    const Mat3 FtdF = F.transpose() * dF;
    const Mat3 dE = 0.5 * (FtdF + FtdF.transpose());
    Mat3 dS = (2 * m.lame_mu) * dE;
    dS.diagonal().array() += m.lame_lambda * dE.trace();
    Mat3 dP = dF * S + F * dS;
    if (m.volume_stiffness > 0) {  // d[k_v (J-1) cof F] = k_v [(cof F : dF) cof F + (J-1) d cof F]
      const Mat3 C = cofactor(F);
      const double J = F.col(0).dot(C.col(0));
      Mat3 dC;
      dC.col(0) = dF.col(1).cross(F.col(2)) + F.col(1).cross(dF.col(2));
      dC.col(1) = dF.col(2).cross(F.col(0)) + F.col(2).cross(dF.col(0));
      dC.col(2) = dF.col(0).cross(F.col(1)) + F.col(0).cross(dF.col(1));
      dP += m.volume_stiffness * ((C.array() * dF.array()).sum() * C + (J - 1) * dC);
    }
    Mat3 vdP = m.volume[i] * dP;
    if (!m.hourglass_weight.empty()) {  // the hourglass energy is quadratic: same form with (dx, dF)
      Mat3 G;
      hourglass_forces(m, dx, i, dF, G, df);
      vdP -= G;
    }
    Vec3 fi = Vec3::Zero();
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const Vec3 g = vdP * Eigen::Map<const Vec3>(D + 3 * a);
      Eigen::Map<Vec3>(df + 3 * idx[a]) -= g;
      fi += g;
    }
    Eigen::Map<Vec3>(df + 3 * i) += fi;
  }
}

double internal_forces_flops(const Model& m) {
  // Per neighbour: F accumulation 3 sub + 9 fma (21 flops), force 9 fma + 6 add (24 flops).
  // Per particle: strain/stress/P ~ 120 flops.
  const double nnz = m.neighbor_offset.back();
  double flops = nnz * 45.0 + m.particle_count * 120.0;
  if (m.volume_stiffness > 0) flops += m.particle_count * 60.0;
  if (!m.hourglass_weight.empty()) flops += nnz * 60.0;
  return flops;
}

}  // namespace palpate
