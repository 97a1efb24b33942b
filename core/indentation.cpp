#include "core/indentation.h"

namespace palpate {

double indentation(const Model& model, const State& state) { return model.touch_height - state.indenter_center[2]; }

}  // namespace palpate
