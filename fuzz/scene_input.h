#pragma once
// The input format of scene_parse_fuzz, shared with its regression tests
// (tests/fuzz_regressions_test.cpp): the scene text, then optionally
// NUL-separated "key=value" overrides (the --set path).
#include <string>
#include <string_view>

#include "core/scene.h"

namespace palpate::fuzz {

struct SceneInput {
  std::string text;
  SceneOverrides overrides;
};

inline SceneInput split_scene_input(std::string_view input) {
  SceneInput out;
  const size_t end = input.find('\0');
  out.text = std::string(input.substr(0, end));
  for (size_t start = end; start != std::string_view::npos && start < input.size();) {
    const size_t next = input.find('\0', start + 1);
    const std::string_view item = input.substr(start + 1, next == std::string_view::npos ? next : next - start - 1);
    const size_t eq = item.find('=');
    if (eq != std::string_view::npos && eq > 0)
      out.overrides.emplace_back(std::string(item.substr(0, eq)), std::string(item.substr(eq + 1)));
    start = next;
  }
  return out;
}

}  // namespace palpate::fuzz
