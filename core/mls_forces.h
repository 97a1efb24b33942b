#pragma once
// Internal forces of the MLS solid with nodal integration (Müller et al. 2004,
// Aras et al.): deformation gradient, the material law's stress (St Venant-Kirchhoff, the
// paper's; corotational; linear; neo-Hookean: Model::law), energy-consistent forces, the
// optional volume-restoring term and the optional hourglass control. Forces are the exact
// negative gradient of mls_strain_energy().
#include <vector>

#include "core/model.h"
#include "core/thread_pool.h"
#include "core/types.h"

namespace palpate {

// Every function here is for an MLS model (model.solid == SolidKind::mls; asserted):
// a hex-FEM model has no support domains. solid.h dispatches on the model.

// f (3 x n, overwritten) = -dU/dx at positions x (3 x n). This overload and the
// differential's without threads allocate the blocked loops' scratch per call (for tests
// and tools); the step passes its State's WorkerThreads, whose scratch is allocated once.
void mls_internal_forces(const Model& model, const Points& x, Points& f);

// The same on threads.count() threads (core/thread_pool.h): the blocked loop's blocks cut
// into count() contiguous ranges of about equal work (a pair of blocks never cut, for the
// corotational law's pairing), thread 0 accumulating its forces into f, thread t > 0 into
// buffer t - 1 of the threads' scratch, then f += buffer 0 + buffer 1 + ... coordinate by
// coordinate, in that order, over count() ranges of coordinates. The split depends on the model and
// the count only, so results are bit-identical between runs for a given count; count 1
// (or the per-particle loops, which stay on one thread) is the function above, bit for
// bit. Other counts differ from it by the order of the sums (round-off).
void mls_internal_forces(const Model& model, const Points& x, Points& f, WorkerThreads& threads);

// f (3 x n, overwritten) = the forces of the listed force blocks' support domains alone (blocks
// ascending, Model::blocks; multirate symplectic Euler, core/rate_schedule.h): every member's
// share of those domains, nothing of the others. Requires the blocked layout. On threads as
// mls_internal_forces above, the list split into ranges of about equal work (the split a
// function of the model, the list and the count, so bit-identical between runs); all blocks
// listed, the forces are mls_internal_forces' bit for bit, on any count of threads.
void mls_internal_forces_of_blocks(const Model& model, const Points& x, const int* blocks, int count, Points& f,
                                   WorkerThreads& threads);

// U(x) = sum_i v_i [ psi(F_i) + k_v/2 (det F_i - 1)^2 ] + hourglass energy, J, psi the law's energy
// density (St Venant-Kirchhoff: 1/2 E:S).
double mls_strain_energy(const Model& model, const Points& x);

// Deformation gradient of particle i: F_i = sum_j (x_j - x_i) d_j^T + C_i.
Mat3 deformation_gradient(const Model& model, const Points& x, int i);

// Material law of the matrix material (Model::lame_lambda, lame_mu; the forces use each
// particle's own, Model::particle_lambda, particle_mu): first Piola stress P (St Venant-Kirchhoff F S, corotational,
// linear or neo-Hookean, + k_v (J - 1) cof F) for deformation gradient F; returns the energy
// density psi, J/m^3 (+infinity for the neo-Hookean law at det F <= 0, where P is finite).
double first_piola_stress(const Model& model, const Mat3& F, Mat3& P);
// The same with particle i's own Lame parameters (Model::particle_lambda, particle_mu), as the
// forces use them (core/stress.h reads the per-particle stress through it).
double particle_first_piola_stress(const Model& model, const Mat3& F, int i, Mat3& P);

// Tangent stiffness, matrix-free. mls_linearize caches F_i and the law's factor (9 x n
// each: S_i for St Venant-Kirchhoff and linear, R_i for the corotational law, F_i^-T for the
// neo-Hookean) at x; mls_force_differential then gives df = (df/dx) dx = -K dx.
void mls_linearize(const Model& model, const Points& x, std::vector<double>& tangent_F,
                      std::vector<double>& tangent_law_factor);
void mls_force_differential(const Model& model, const std::vector<double>& tangent_F,
                        const std::vector<double>& tangent_law_factor, const Points& dx, Points& df);
// The same on threads.count() threads, split as mls_internal_forces (the linearisation by
// particle ranges: no sums, bit-identical to one thread).
void mls_linearize(const Model& model, const Points& x, std::vector<double>& tangent_F,
                   std::vector<double>& tangent_law_factor, WorkerThreads& threads);
void mls_force_differential(const Model& model, const std::vector<double>& tangent_F,
                            const std::vector<double>& tangent_law_factor, const Points& dx, Points& df,
                            WorkerThreads& threads);

// The tangent product for up to kMaxDifferentials directions in one sweep over the neighbour
// pairs: df[q] = (df/dx) dx[q] (= -K dx[q]), q < count, each equal to mls_force_differential's
// (the same arithmetic per direction; the tangent's F_i, S_i or R_i, the weights and, for the
// corotational law, its rotation's linear system gathered or formed once for all of them).
// On the calling thread, with scratch's rows (whatever its thread count); without the blocked
// loops (a Model without them) one product after the other. dx[q] and df[q] must be distinct
// arrays, 3 x n.
inline constexpr int kMaxDifferentials = 3;
void mls_force_differentials(const Model& model, const std::vector<double>& tangent_F,
                             const std::vector<double>& tangent_law_factor, int count, const Points* const* dx,
                             Points* const* df, WorkerThreads& scratch);

// Floating-point operations of one mls_internal_forces call at positions x (for the
// benchmark's GFLOP/s), counted by hand from the blocked loop of the model's law; for the
// corotational law the polar iterations at x are counted by running them.
double mls_internal_forces_flops(const Model& model, const Points& x);

namespace detail {
// Whether mls_internal_forces and mls_force_differential take the vectorised loops over
// Model::blocks (true) or the per-particle reference loops (a Model without blocks, or
// with hourglass control but without its blocked terms). For tests: a copy of a Model with its blocks cleared runs the
// reference loops on the same support domains, weights and volumes.
bool uses_blocked_loops(const Model& model);

// The polar rotation of the per-particle formulas (Higham's scaled Newton iteration to a
// squared change of 1e-24), and the vectorised one of the blocked corotational loop on
// four matrices at once (the polynomial iteration of docs/physics.md (1.17), else the
// packed scaled Newton iteration); the latter returns its iteration count, or 0 when it
// leaves the lanes to the former (a (nearly) singular F, or no convergence), R then
// unspecified. schulz_rotation_blocked is the polynomial iteration alone (0: a lane
// outside its basin or not converged).
Mat3 polar_rotation(const Mat3& F);
int polar_rotation_blocked(const Mat3 (&F)[Model::block_width], Mat3 (&R)[Model::block_width]);
int schulz_rotation_blocked(const Mat3 (&F)[Model::block_width], Mat3 (&R)[Model::block_width]);
// ln a of the neo-Hookean blocked loop (packed), a in [1e-300, 1e300].
void log_blocked(const double (&a)[Model::block_width], double (&log_a)[Model::block_width]);

// The blocked force loop's memory work alone, for the benchmark: the same gathers, F
// and scatters over the same slots, with the law replaced by P = F
// (9 multiplications per particle; no volume term, no hourglass control), with the same
// conversions to and from padded rows, in scratch's rows. Its time is a floor under every
// law's force evaluation on the model. Returns the flops it does, counted as
// mls_internal_forces_flops counts the shared part. Requires the blocked layout.
double pair_loop_floor(const Model& model, const Points& x, Points& f, WorkerThreads& scratch);
}  // namespace detail

}  // namespace palpate
