// libFuzzer target: palpate::parse_scene (core/scene.h), the JSON scene parser
// shared by scene files, --set and the wire.
//
// Input (scene_input.h): the scene text, then optionally NUL-separated
// "key=value" overrides. The contract: a scene is returned or a SceneError
// thrown; any other exception, a crash or a sanitizer report is a bug.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "core/scene.h"
#include "fuzz/scene_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto input = palpate::fuzz::split_scene_input({reinterpret_cast<const char*>(data), size});
  try {
    palpate::parse_scene(input.text, "<fuzz>", PALPATE_SOURCE_DIR "/scenes", input.overrides);
  } catch (const palpate::SceneError&) {
  }
  return 0;
}
