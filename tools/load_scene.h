#pragma once
// What every local tool does first: load and validate a scene file (with its --set
// overrides) and build its model. On failure the message (file, field, reason) goes to
// stderr behind the program's name and the tool exits with status 1.
#include <iostream>
#include <optional>
#include <string>

#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"

namespace palpate::tools {

struct LoadedScene {
  Scene scene;
  Model model;
  Options opt;  // options_of(scene)
};

inline std::optional<LoadedScene> load_scene_and_model(const char* program, const std::string& file,
                                                       const SceneOverrides& overrides) {
  try {
    Scene scene = load_scene(file, overrides);
    Model model = build_model(scene);
    const Options opt = options_of(scene);
    return LoadedScene{std::move(scene), std::move(model), opt};
  } catch (const std::exception& e) {
    std::cerr << program << ": " << e.what() << "\n";
    return std::nullopt;
  }
}

}  // namespace palpate::tools
