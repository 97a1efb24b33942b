#pragma once
// The elastic solid of a Model, whichever model the scene chose ("mls": the
// meshless solid of mls_forces.h; "hex_fem": the hexahedral FEM of hex_fem.h).
// Integrators and tools call these; they dispatch once per call.
#include "core/model.h"
#include "core/state.h"
#include "core/types.h"

namespace palpate {

// f (3 x n, overwritten) = internal elastic forces at positions x.
void elastic_forces(const Model& model, const Points& x, Points& f);
// The same on the threads of a State (Workspace::threads, Options' integrator.threads): the
// MLS loops split over them (mls_forces.h); the hex FEM on the calling thread.
void elastic_forces(const Model& model, const Points& x, Points& f, WorkerThreads& threads);
// Strain energy at x, J.
double elastic_energy(const Model& model, const Points& x);
// Tangent stiffness, matrix-free: cache the linearisation point x in `work`,
// then df = (df/dx) dx = -K dx. Both on work.threads (MLS; the hex FEM on the calling thread).
void linearize_elastic(const Model& model, const Points& x, Workspace& work);
void elastic_force_differential(const Model& model, Workspace& work, const Points& dx, Points& df);
// The same for `count` directions (at most 3: mls_forces.h kMaxDifferentials), df[q] = -K dx[q],
// each equal to elastic_force_differential's. MLS on one thread (work.threads.count() == 1): one
// sweep over the neighbour pairs for all of them (mls_force_differentials); otherwise, and for
// the hex FEM, one product after the other.
void elastic_force_differentials(const Model& model, Workspace& work, int count, const Points* const* dx,
                                 Points* const* df);

}  // namespace palpate
