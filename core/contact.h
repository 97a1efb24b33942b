#pragma once
// Frictionless unilateral contact between the rigid sphere indenter and the
// particles, with Lagrange multipliers (docs/physics.md §2).
//
// After the integrator's free motion (no contact forces), two projections:
// 1. Positions. The gaps g_i = |x_i - c| - R of the candidate particles (negative
//    free gap) are linearised in the multipliers lambda and the sphere's vertical
//    motion: g' = g + W lambda, W = dt^2 J M^-1 J^T with the sphere's column
//    included (the Delassus operator). The linear complementarity problem
//    lambda >= 0, g' >= 0, lambda . g' = 0 (Signorini) is solved exactly by
//    principal pivoting from the previous step's contact set (projected Gauss-Seidel
//    finishes if pivoting does not settle), on W = D + U U^T by the Woodbury identity
//    (2.19), O(m) a pivot; x += dt^2 M^-1 J^T lambda.
// 2. Velocities. For the particles touching after (1), the relative normal
//    velocities u = J v must not approach: u' = u + (W / dt) mu >= 0, mu >= 0,
//    mu . u' = 0; v += dt M^-1 J^T mu. mu (N) is the contact force of the step
//    (momentum exchanged / dt) and is what the state reports.
// Both are M-metric projections, so momentum is conserved and the rest state is a
// fixed point of every integrator (the free motion pushes in, the projections
// push back exactly). For implicit Euler, M is replaced by the step operator A, and W is
// not formed (one CG solve per candidate): the LCPs are solved by the splitting (2.18) on
// compliance columns cached across steps (2.17, Workspace::compliance), one CG solve of A
// per iteration, to the same solution (docs/physics.md §2, "Implicit Euler's contact").
#include "core/model.h"
#include "core/options.h"
#include "core/state.h"

namespace palpate {

// The coupled response of an implicit step: out = A^-1 load over the free DOFs, to a
// residual |load - A out| <= residual_norm (N). Returns the iterations used, -1 if the
// residual was not reached. The operator must not change during one solve_contact.
class LinearResponse {
 public:
  virtual ~LinearResponse() = default;
  virtual int solve(const Points& load, Points& out, double residual_norm) = 0;
};

// The first stage of solve_contact: the candidates (free particles inside the sphere after
// the free motion, and those in contact at the previous step, whose forces the free motion
// carried) into state.out.contact_candidate, with their free gaps (2.2), unit normals and
// previous forces (vector, and multiplier along this step's normal) in state.work (gap,
// normal, previous_force, previous_multiplier); clears the step's contact outputs. Returns
// the number of candidates m.
int gather_contact_candidates(const Model& model, State& state);

// Solves and applies the contact of one step. With coupled == nullptr the
// particles respond through their lumped inverse masses (explicit integrators); with the
// step operator A of implicit Euler, through A^-1 (state.out counts its CG work). Returns
// contact_not_converged when neither pivoting nor projected Gauss-Seidel met the
// tolerance (the best multipliers found are still applied).
StepStatus solve_contact(const Model& model, const Options& opt, State& state, LinearResponse* coupled = nullptr);

// Solves the LCP  w = g + W lambda, lambda >= 0, w >= -tolerance, lambda . w = 0 for a
// symmetric positive definite W (m x m, row-major). Pivoting starts from the active set
// initial_active (m flags; nullptr: {g < 0}). Returns the number of pivots (or sweeps)
// used, or -1 when it did not converge. Scratch comes from `work`.
int solve_signorini_lcp(int m, const double* W, const double* g, double* lambda, double tolerance,
                        int max_iterations, Workspace& work, const int* initial_active = nullptr);

// The same LCP and pivoting for W = diag(d) + U U^T, d > 0 (m), U m x 3 (row a at u + 3a),
// the explicit integrators' Delassus operator (2.4): each pivot solves W_AA by the
// Woodbury identity (2.19), O(m) instead of the dense O(k^3) factorisation.
int solve_signorini_lcp_lumped(int m, const double* d, const double* u, const double* g, double* lambda,
                               double tolerance, int max_iterations, Workspace& work,
                               const int* initial_active = nullptr);

}  // namespace palpate
