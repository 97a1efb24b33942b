#include "core/solid.h"

#include "core/hex_fem.h"
#include "core/mls_forces.h"

namespace palpate {

void elastic_forces(const Model& model, const Points& x, Points& f) {
  if (model.solid == SolidKind::hex_fem)
    hex_internal_forces(model.hex, model.rest_position, x, f);
  else
    internal_forces(model, x, f);
}

double elastic_energy(const Model& model, const Points& x) {
  return model.solid == SolidKind::hex_fem ? hex_strain_energy(model.hex, model.rest_position, x)
                                           : strain_energy(model, x);
}

void linearize_elastic(const Model& model, const Points& x, Workspace& work) {
  if (model.solid == SolidKind::hex_fem)
    hex_linearize(model.hex, x, work.cached_F);  // element rotations
  else
    linearize_forces(model, x, work.cached_F, work.cached_S);
}

void elastic_force_differential(const Model& model, const Workspace& work, const Points& dx, Points& df) {
  if (model.solid == SolidKind::hex_fem)
    hex_force_differential(model.hex, work.cached_F, dx, df);
  else
    force_differential(model, work.cached_F, work.cached_S, dx, df);
}

}  // namespace palpate
