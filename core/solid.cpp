#include "core/solid.h"

#include "core/hex_fem.h"
#include "core/mls_forces.h"

namespace palpate {

void elastic_forces(const Model& model, const Points& x, Points& f) {
  if (model.solid == SolidKind::hex_fem)
    hex_internal_forces(model.hex, model.rest_position, x, f);
  else
    mls_internal_forces(model, x, f);
}

void elastic_forces(const Model& model, const Points& x, Points& f, WorkerThreads& threads) {
  if (model.solid == SolidKind::hex_fem)
    hex_internal_forces(model.hex, model.rest_position, x, f);
  else
    mls_internal_forces(model, x, f, threads);
}

double elastic_energy(const Model& model, const Points& x) {
  return model.solid == SolidKind::hex_fem ? hex_strain_energy(model.hex, model.rest_position, x)
                                           : mls_strain_energy(model, x);
}

void linearize_elastic(const Model& model, const Points& x, Workspace& work) {
  if (model.solid == SolidKind::hex_fem)
    hex_linearize(model.hex, x, work.tangent_F);  // element rotations (hex FEM)
  else
    mls_linearize(model, x, work.tangent_F, work.tangent_law_factor, work.threads);
}

void elastic_force_differential(const Model& model, Workspace& work, const Points& dx, Points& df) {
  if (model.solid == SolidKind::hex_fem)
    hex_force_differential(model.hex, work.tangent_F, dx, df);
  else
    mls_force_differential(model, work.tangent_F, work.tangent_law_factor, dx, df, work.threads);
}

void elastic_force_differentials(const Model& model, Workspace& work, int count, const Points* const* dx,
                                 Points* const* df) {
  if (model.solid == SolidKind::mls && work.threads.count() == 1)
    return mls_force_differentials(model, work.tangent_F, work.tangent_law_factor, count, dx, df, work.threads);
  for (int q = 0; q < count; ++q) elastic_force_differential(model, work, *dx[q], *df[q]);
}

}  // namespace palpate
