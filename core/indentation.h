#pragma once
// The indentation measure (docs/physics.md §2).
#include "core/model.h"
#include "core/state.h"

namespace palpate {

// d = travel of the indenter below the height at which it touches the undeformed
// surface (Model::touch_height), m. Positive when pressing. On a lattice with the
// sphere centred between particles this includes the strain-free sinking between
// them (docs/physics.md §2), as a continuum comparison with Hertz requires.
double indentation(const Model& model, const State& state);

}  // namespace palpate
