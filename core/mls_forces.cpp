// The MLS solid's forces, tangent and energy (core/mls_forces.h): the public functions, each
// dispatching on the model's material law (core/laws/laws.h) to the loops of core/mls_loops.h.
#include "core/mls_forces.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include "core/laws/laws.h"
#include "core/mls_loops.h"

namespace palpate {

using namespace mls;

bool detail::uses_blocked_loops(const Model& model) { return use_blocks(model); }

Mat3 detail::polar_rotation(const Mat3& F) { return mls::polar_rotation(F); }

namespace {
void to_lanes(const Mat3 (&F)[Model::block_width], Mat3Lanes (&F_lanes)[1]) {
  for (int l = 0; l < kLanes; ++l)
    for (int k = 0; k < 9; ++k) F_lanes[0].m[k][l] = F[l](k % 3, k / 3);
}
void from_lanes(const Mat3Lanes (&R_lanes)[1], Mat3 (&R)[Model::block_width]) {
  for (int l = 0; l < kLanes; ++l)
    for (int k = 0; k < 9; ++k) R[l](k % 3, k / 3) = R_lanes[0].m[k][l];
}
}  // namespace

int detail::polar_rotation_blocked(const Mat3 (&F)[Model::block_width], Mat3 (&R)[Model::block_width]) {
  Mat3Lanes F_lanes[1], R_lanes[1];
  to_lanes(F, F_lanes);
  int iterations = schulz_rotation_lanes<1>(F_lanes, R_lanes);
  if (iterations == 0) iterations = polar_rotation_lanes<1>(F_lanes, R_lanes);
  from_lanes(R_lanes, R);
  return iterations;
}

int detail::schulz_rotation_blocked(const Mat3 (&F)[Model::block_width], Mat3 (&R)[Model::block_width]) {
  Mat3Lanes F_lanes[1], R_lanes[1];
  to_lanes(F, F_lanes);
  const int iterations = schulz_rotation_lanes<1>(F_lanes, R_lanes);
  from_lanes(R_lanes, R);
  return iterations;
}

double detail::pair_loop_floor(const Model& m, const Points& x, Points& f, WorkerThreads& scratch) {
  assert(use_blocks(m) && "pair_loop_floor needs the blocked layout");
  const int n = m.particle_count;
  loop_on_rows(m, scratch, x.data(), f.data(), [&](int b_begin, int b_end, const double* x_rows, double* f_rows) {
    for (int b = b_begin; b < b_end; ++b) {
      const Block& block = m.blocks[b];
      int i[kLanes];
      block_particles(block, i);
      Mat3Lanes F, vP;
      PALPATE_UNROLL
      for (int k = 0; k < 9; ++k) F.m[k] = load(block.rest_correction[k]);
      add_gradient<Rows>(m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end, x_rows, i, F);
      const Lanes v = load(block.volume);
      PALPATE_UNROLL
      for (int k = 0; k < 9; ++k) vP.m[k] = v * F.m[k];
      scatter_forces<Rows>(block, m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end, vP, i,
                           block.lanes, f_rows);
    }
  });
  return m.neighbor_offset.back() * 39.0 + n * (18.0 + 9.0);
}

void detail::log_blocked(const double (&a)[Model::block_width], double (&log_a)[Model::block_width]) {
  Lanes v;
  std::memcpy(&v, a, sizeof v);
  const Lanes r = log_lanes(v);
  std::memcpy(log_a, &r, sizeof r);
}

Mat3 deformation_gradient(const Model& model, const Points& x, int i) { return gradient_at(model, x.data(), i); }

double first_piola_stress(const Model& model, const Mat3& F, Mat3& P) {
  return with_law(model.law, [&]<class Law>() { return piola_stress<Law>(model, F, model.lame_lambda, model.lame_mu, P); });
}

double particle_first_piola_stress(const Model& model, const Mat3& F, int i, Mat3& P) {
  return with_law(model.law, [&]<class Law>() {
    return piola_stress<Law>(model, F, model.particle_lambda[i], model.particle_mu[i], P);
  });
}

void mls_internal_forces(const Model& m, const Points& x, Points& f) {
  WorkerThreads scratch;  // allocates the loop's rows: the stepping code passes its own
  mls_internal_forces(m, x, f, scratch);
}

void mls_internal_forces(const Model& m, const Points& x, Points& f, WorkerThreads& threads) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  if (!use_blocks(m)) {
    f.setZero();
    return with_law(m.law, [&]<class Law>() { internal_forces_per_particle<Law>(m, x.data(), f.data()); });
  }
  with_blocked_variant(m, [&]<class Law, bool volume_term, bool hourglass>() {
    if (threads.count() == 1)
      return loop_on_rows(m, threads, x.data(), f.data(), [&](int b_begin, int b_end, const double* x_rows, double* out) {
        internal_forces_blocked<Law, Rows, volume_term, hourglass>(m, b_begin, b_end, x_rows, out);
      });
    scatter_in_parallel(m, f.data(), threads, [&](int b_begin, int b_end, double* out) {
      internal_forces_blocked<Law, Columns, volume_term, hourglass>(m, b_begin, b_end, x.data(), out);
    });
  });
}

void mls_internal_forces_of_blocks(const Model& m, const Points& x, const int* blocks, int count, Points& f,
                                   WorkerThreads& threads) {
  assert(use_blocks(m) && "the forces of listed blocks need the blocked layout");
  with_blocked_variant(m, [&]<class Law, bool volume_term, bool hourglass>() {
    if (threads.count() == 1)
      return loop_on_rows(m, threads, x.data(), f.data(), [&](int, int, const double* x_rows, double* out) {
        internal_forces_listed<Law, Rows, volume_term, hourglass>(m, blocks, count, x_rows, out);
      });
    scatter_in_parallel(
        m, f.data(), threads,
        [&](int k_begin, int k_end, double* out) {
          internal_forces_listed<Law, Columns, volume_term, hourglass>(m, blocks + k_begin, k_end - k_begin, x.data(), out);
        },
        blocks, count);
  });
}

double mls_strain_energy(const Model& m, const Points& x) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  return with_law(m.law, [&]<class Law>() {
    double U = 0;
    for (int i = 0; i < m.particle_count; ++i) {
      const Mat3 F = gradient_at(m, x.data(), i);
      Mat3 P;
      U += m.volume[i] * piola_stress<Law>(m, F, m.particle_lambda[i], m.particle_mu[i], P);
      if (!m.hourglass_weight.empty()) {
        Mat3 G;
        U += hourglass_forces(m, x.data(), i, F, G, nullptr);
      }
    }
    return U;
  });
}

void mls_linearize(const Model& m, const Points& x, std::vector<double>& tangent_F,
                      std::vector<double>& tangent_law_factor) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  tangent_F.resize(9 * static_cast<size_t>(m.particle_count));
  tangent_law_factor.resize(9 * static_cast<size_t>(m.particle_count));
  with_law(m.law, [&]<class Law>() { linearize_particles<Law>(m, x, 0, m.particle_count, tangent_F, tangent_law_factor); });
}

void mls_linearize(const Model& m, const Points& x, std::vector<double>& tangent_F,
                   std::vector<double>& tangent_law_factor, WorkerThreads& threads) {
  if (threads.count() == 1) return mls_linearize(m, x, tangent_F, tangent_law_factor);
  tangent_F.resize(9 * static_cast<size_t>(m.particle_count));
  tangent_law_factor.resize(9 * static_cast<size_t>(m.particle_count));
  const int T = threads.count(), n = m.particle_count;
  with_law(m.law, [&]<class Law>() {
    threads.pool->run([&](int t) {
      linearize_particles<Law>(m, x, static_cast<int>(int64_t{n} * t / T), static_cast<int>(int64_t{n} * (t + 1) / T),
                               tangent_F, tangent_law_factor);
    });
  });
}


void mls_force_differential(const Model& m, const std::vector<double>& tangent_F,
                            const std::vector<double>& tangent_law_factor, const Points& dx, Points& df) {
  WorkerThreads scratch;  // allocates the loop's rows: the stepping code passes its own
  mls_force_differential(m, tangent_F, tangent_law_factor, dx, df, scratch);
}

void mls_force_differential(const Model& m, const std::vector<double>& tangent_F,
                            const std::vector<double>& tangent_law_factor, const Points& dx, Points& df,
                            WorkerThreads& threads) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  if (!use_blocks(m)) {
    df.setZero();
    return with_law(m.law, [&]<class Law>() {
      force_differential_per_particle<Law>(m, tangent_F.data(), tangent_law_factor.data(), dx.data(), df.data());
    });
  }
  const double *F = tangent_F.data(), *S = tangent_law_factor.data();
  with_blocked_variant(m, [&]<class Law, bool volume_term, bool hourglass>() {
    if (threads.count() == 1)
      return loop_on_rows(m, threads, dx.data(), df.data(), [&](int b_begin, int b_end, const double* dx_rows, double* out) {
        const double* in[1] = {dx_rows};
        double* outs[1] = {out};
        force_differentials_blocked<Law, Rows, volume_term, hourglass, 1>(m, b_begin, b_end, F, S, in, outs);
      });
    scatter_in_parallel(m, df.data(), threads, [&](int b_begin, int b_end, double* out) {
      const double* in[1] = {dx.data()};
      double* outs[1] = {out};
      force_differentials_blocked<Law, Columns, volume_term, hourglass, 1>(m, b_begin, b_end, F, S, in, outs);
    });
  });
}

void mls_force_differentials(const Model& m, const std::vector<double>& tangent_F,
                             const std::vector<double>& tangent_law_factor, int count, const Points* const* dx,
                             Points* const* df, WorkerThreads& scratch) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  assert(count >= 0 && count <= kMaxDifferentials);
  if (count == 0) return;
  if (!use_blocks(m)) {  // the per-particle reference loop: one product after the other
    for (int q = 0; q < count; ++q) mls_force_differential(m, tangent_F, tangent_law_factor, *dx[q], *df[q], scratch);
    return;
  }
  const int n = m.particle_count;
  const size_t stride = kRow * static_cast<size_t>(n);
  double* rows = scratch.row_buffers(2 * count, n);  // the directions' rows, then their forces'
  const double* in[kMaxDifferentials];
  double* out[kMaxDifferentials];
  for (int q = 0; q < count; ++q) {
    double* in_rows = rows + q * stride;
    to_rows(dx[q]->data(), n, in_rows);
    in[q] = in_rows;
    out[q] = rows + (count + q) * stride;
    std::fill(out[q], out[q] + stride, 0.0);
  }
  const int blocks = static_cast<int>(m.blocks.size());
  const double *F = tangent_F.data(), *S = tangent_law_factor.data();
  with_blocked_variant(m, [&]<class Law, bool volume_term, bool hourglass>() {
    switch (count) {
      case 1: force_differentials_blocked<Law, Rows, volume_term, hourglass, 1>(m, 0, blocks, F, S, in, out); break;
      case 2: force_differentials_blocked<Law, Rows, volume_term, hourglass, 2>(m, 0, blocks, F, S, in, out); break;
      default: force_differentials_blocked<Law, Rows, volume_term, hourglass, 3>(m, 0, blocks, F, S, in, out); break;
    }
  });
  for (int q = 0; q < count; ++q) from_rows(out[q], n, df[q]->data());
}

double mls_internal_forces_flops(const Model& m, const Points& x) {
  // Floating-point operations (an FMA counts two; a division, square root or logarithm one)
  // of the arithmetic the force loop needs, as the code does it; padding slots and lanes of
  // the blocked loop are not counted.
  const double nnz = m.neighbor_offset.back(), n = m.particle_count;
  if (use_blocks(m)) {
    // Every law, per neighbour pair: F += (x_j - x_i) d_j^T 3 sub + 9 fma = 21;
    // g = v_i P_i d_j 3 x (mul + 2 fma) = 15; f_j -= g 3: 39. Per particle:
    // f_i -= v_i P_i d_i 15 + 3 = 18. Volume term per particle: cof F
    // 9 x (mul + fma) = 27, J 5, k_v v (J - 1) 3, P += 9 fma 18: 53.
    double per_particle = 18.0 + (m.volume_stiffness > 0 ? 53.0 : 0.0);
    // The law's stress (Law::flops_per_particle), and what its iterations spend at x.
    auto gradients = [&](int b, Mat3Lanes& F) {
      const Block& block = m.blocks[b];
      int i[kLanes];
      block_particles(block, i);
      PALPATE_UNROLL
      for (int k = 0; k < 9; ++k) F.m[k] = load(block.rest_correction[k]);
      add_gradient<Columns>(m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end, x.data(), i, F);
      return block.lanes;
    };
    double polar = 0;
    with_law(m.law, [&]<class Law>() {
      per_particle += Law::flops_per_particle;
      polar = Law::iteration_flops(m, gradients);
    });
    if (!m.hourglass_weight.empty()) {
      // Hourglass control (1.9a), per pair: B += x_ij e_ij^T 9 fma 18, s += k x_ij 3 fma 6; in
      // the scatter x_ij 3 sub, k x_ij - F e_ij 3 x (mul + 3 fma) = 21: 48. Per particle: F H
      // 9 x (mul + 2 fma) = 45, T += F H - B 18; s - F e_i 3 x (mul + 3 fma) = 21: 84. Only in
      // the blocks that have it (the loop skips the others).
      double hg_pairs = 0, hg_particles = 0;
      for (size_t b = 0; b < m.blocks.size(); ++b)
        if (m.block_hourglass[b].active)
          for (int l = 0; l < m.blocks[b].lanes; ++l) {
            const int i = m.blocks[b].particle[l];
            hg_pairs += m.neighbor_offset[i + 1] - m.neighbor_offset[i];
            hg_particles += 1;
          }
      return nnz * 39.0 + hg_pairs * 51.0 + n * per_particle + hg_particles * 84.0 + polar;
    }
    return nnz * 39.0 + n * per_particle + polar;
  }
  // Per particle loop (a model without the blocked layout): per pair 21 (F) + 15 (T d_j) + 3 (f_j)
  // + 3 (f_i sum) = 42, per particle about 130 (E, S, P with Eigen 3x3 products; energy density)
  // plus the volume term, and the hourglass residuals r_ij = x_ij - F X_ij, G += kw r X^T and its
  // direct forces: about 60 per pair. (The St Venant-Kirchhoff law's count; the per-particle
  // loop is the reference, not timed.)
  return nnz * (42.0 + (m.hourglass_weight.empty() ? 0.0 : 60.0)) +
         n * (130.0 + (m.volume_stiffness > 0 ? 60.0 : 0.0));
}


}  // namespace palpate
