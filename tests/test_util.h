#pragma once
// Helpers shared by the tests: models from inline scene text.
#include <string>

#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"

namespace palpate::test {

// True in the sanitized builds (PALPATE_SANITIZE): there the static solves' small Eigen
// algebra runs 60-100x slower than in Release, so the heaviest tests solve smaller problems
// that take the same code paths, with the same checks.
#ifdef PALPATE_SANITIZED
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif

// A scene from inline JSON (validated like a file).
inline Scene scene_from_json(const std::string& json) { return parse_scene(json, "inline-test-scene", "."); }

inline Model model_from_json(const std::string& json) { return build_model(scene_from_json(json)); }

// What a test that steps needs: the scene, its model and its options.
struct Setup {
  Scene scene;
  Model model;
  Options opt;
};
inline Setup setup_from(const Scene& scene) { return {scene, build_model(scene), options_of(scene)}; }
inline Setup setup_from_json(const std::string& json) { return setup_from(scene_from_json(json)); }

}  // namespace palpate::test
