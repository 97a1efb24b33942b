// Inputs the fuzzers (fuzz/) found crashing, fed to the same functions: every
// file under fuzz/regressions/<target>/ and a minimal case of each finding.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "core/scene.h"
#include "fuzz/scene_input.h"

namespace palpate {
namespace {

namespace fs = std::filesystem;

std::string read_file(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// parse_scene's contract: a Scene or a SceneError, nothing else.
TEST(FuzzRegressions, SceneParserThrowsOnlySceneErrors) {
  const fs::path dir = fs::path(PALPATE_SOURCE_DIR) / "fuzz" / "regressions" / "scene_parse_fuzz";
  int count = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const auto input = fuzz::split_scene_input(read_file(entry.path()));
    try {
      parse_scene(input.text, "<fuzz>", fs::path(PALPATE_SOURCE_DIR) / "scenes", input.overrides);
    } catch (const SceneError&) {
    } catch (const std::exception& e) {
      ADD_FAILURE() << entry.path().filename() << ": " << e.what();
    }
    ++count;
  }
  EXPECT_GT(count, 0);
}

// A bare override value is kept as a string even when it is not UTF-8; the
// message describing it used to throw nlohmann's type_error 316 instead.
TEST(FuzzRegressions, OverrideWithInvalidUtf8IsASceneError) {
  try {
    parse_scene("{}", "inline", ".", {{"mls.neighbors", "4\xe8"}});
    FAIL() << "accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/mls/neighbors");
    EXPECT_NE(e.reason().find("expected a number, got string"), std::string::npos) << e.reason();
  }
}

}  // namespace
}  // namespace palpate
