// The user guide's examples (docs/guide/), built and run so that they cannot rot:
//  - your-own-tissue.md shows docs/guide/examples/my_tissue.json verbatim, palpate-verify
//    runs it to an error figure, and the server serves it as the guide says;
//  - running-a-study.md shows docs/guide/examples/my_study.json verbatim, and palpate-study
//    runs and merges it;
//  - examples/haptic_client.cpp against the real palpate-server renders a force, over TCP and
//    over TLS with an access token (the commands haptic-device.md shows);
//  - examples/embed_core.cpp presses the haptic cube to within 10 % of Hertz, and every line of
//    code embedding-the-core.md shows is one of its lines.
// PALPATE_*_BIN and PALPATE_SOURCE_DIR come from tests/CMakeLists.txt.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "cli/child_process.h"
#include "tests/test_server.h"

namespace palpate {
namespace {

using cli::ProgramResult;
using cli::run_program;
using test::ServerProcess;

const std::string kSource = PALPATE_SOURCE_DIR;
const std::string kScene = kSource + "/docs/guide/examples/my_tissue.json";
const std::vector<std::string> kTcpOnly;  // the server's arguments beyond ServerProcess's own: no --http

// A program's time limit: the sanitized builds (scripts/test.sh --sanitize) step several times slower.
std::chrono::seconds limit(int seconds) {
#ifdef PALPATE_SANITIZED
  return std::chrono::seconds(5 * seconds);
#else
  return std::chrono::seconds(seconds);
#endif
}

// A fresh folder under /tmp, removed with everything in it at the end of the test.
struct TempDir {
  TempDir() {
    char name[] = "/tmp/palpate-guide-XXXXXX";
    path = mkdtemp(name);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::string path;
};

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  EXPECT_TRUE(in) << "cannot read " << path;
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The first number after `label` in `text` (NaN when the label is missing), e.g. the X of
// "peak rendered force X N".
double number_after(const std::string& text, const std::string& label) {
  const auto at = text.find(label);
  if (at == std::string::npos) return NAN;
  return std::strtod(text.c_str() + at + label.size(), nullptr);
}

// The contents of every ```json fenced block of a markdown text.
std::vector<std::string> json_blocks(const std::string& markdown) {
  std::vector<std::string> blocks;
  const std::string open = "\n```json\n", close = "\n```\n";
  for (auto at = markdown.find(open); at != std::string::npos; at = markdown.find(open, at + 1)) {
    const auto begin = at + open.size();
    const auto end = markdown.find(close, begin - 1);
    if (end == std::string::npos) break;
    blocks.push_back(markdown.substr(begin, end + 1 - begin));  // with its last newline, as the file ends
  }
  return blocks;
}

// The ```json block of `markdown` that holds `marker` must be `file`, byte for byte, and be
// the only one that holds it.
void expect_shown_verbatim(const std::string& markdown, const std::string& file, const std::string& marker) {
  const std::string text = read_file(kSource + "/" + file);
  int shown = 0;
  for (const std::string& b : json_blocks(read_file(kSource + "/" + markdown)))
    if (b.find(marker) != std::string::npos) {
      ++shown;
      EXPECT_EQ(b, text) << markdown << " must show " << file << " as it is";
    }
  EXPECT_EQ(shown, 1) << markdown << " shows " << file << " once, in a ```json block";
}

TEST(GuideTissue, TheMarkdownShowsTheSceneFileVerbatim) {
  expect_shown_verbatim("docs/guide/your-own-tissue.md", "docs/guide/examples/my_tissue.json",
                        "\"name\": \"my_tissue\"");
}

// The guide's check: the dome's curvature for Hertz, the stored converged reference of the same body.
TEST(GuideTissue, PalpateVerifyPrintsAnErrorFigure) {
  const ProgramResult r =
      run_program({PALPATE_VERIFY_BIN, "--scene", kScene, "--forces", "0.05,0.262", "--surface-radius", "0.05",
                   "--reference", kSource + "/scenes/references/palpation_dome.json", "--quiet"},
                  limit(60));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("scene my_tissue: 6872 particles"), std::string::npos) << r.out;
  const double hertz = number_after(r.out, "L2 error against Hertz: ");
  EXPECT_TRUE(std::isfinite(hertz) && hertz >= 0) << r.out;
  const double reference = number_after(r.out, "against the converged reference: ");
  EXPECT_LT(reference, 2.0) << "the guide says: within about 1 % of the converged reference\n" << r.out;
}

// The guide's server command: the scene as the server's default, the mesh's folder as --scene-dir.
TEST(GuideTissue, TheServerServesItAndADeviceFeelsIt) {
  ServerProcess server({"--scene", kScene, "--scene-dir", kSource + "/scenes"});
  const ProgramResult r = run_program({PALPATE_HAPTIC_CLIENT_BIN, "--connect", server.address(), "--scene", "",
                                       "--seconds", "0.5"}, limit(60));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("scene my_tissue: 6872 particles"), std::string::npos) << r.out;
  EXPECT_GT(number_after(r.out, "peak rendered force "), 0.0) << r.out;
}

TEST(GuideStudy, TheMarkdownShowsThePlanVerbatim) {
  expect_shown_verbatim("docs/guide/running-a-study.md", "docs/guide/examples/my_study.json",
                        "\"name\": \"dome_neighbors\"");
}

// The guide's study: its cases, run in one process, merged into the table, each case measured
// against the scene's stored converged reference.
TEST(GuideStudy, ThePlanRunsAndMerges) {
  const std::string plan = kSource + "/docs/guide/examples/my_study.json", scenes = kSource + "/scenes";
  const ProgramResult count = run_program({PALPATE_STUDY_BIN, plan, "--scenes", scenes, "--count"}, limit(20));
  ASSERT_EQ(count.status, 0) << count.err;
  EXPECT_EQ(count.out, "3\n");
#ifdef PALPATE_SANITIZED
  // The three presses of the dome take 54 s under ASan + UBSan and run nothing of palpate-study
  // that StudyTest does not run there; the Release suite runs them and checks their errors.
  GTEST_SKIP() << "the plan's presses run in the Release suite (palpate-study runs under the sanitizers in StudyTest)";
#endif
  const TempDir dir;
  const std::string& out = dir.path;
  const ProgramResult all =
      run_program({PALPATE_STUDY_BIN, plan, "--scenes", scenes, "--all", "--out", out, "--quiet"}, limit(120));
  ASSERT_EQ(all.status, 0) << all.err;
  const ProgramResult merge = run_program({PALPATE_STUDY_BIN, "merge", plan, "--out", out, "--no-plot"}, limit(60));
  ASSERT_EQ(merge.status, 0) << merge.err;
  std::istringstream csv(read_file(out + "/study.csv"));
  std::vector<std::vector<std::string>> rows;
  for (std::string line; std::getline(csv, line);) {
    rows.emplace_back();
    std::istringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) rows.back().push_back(cell);
  }
  ASSERT_EQ(rows.size(), 1u + 3 * 2) << "a header and a row per case and force";
  const auto column = std::find(rows[0].begin(), rows[0].end(), "l2_error_reference") - rows[0].begin();
  for (size_t r = 1; r < rows.size(); ++r) {
    ASSERT_LT(static_cast<size_t>(column), rows[r].size());
    const double l2 = std::strtod(rows[r][column].c_str(), nullptr);
    EXPECT_TRUE(l2 > 0 && l2 < 0.02) << "case " << rows[r][0] << ": L2 error against the reference " << rows[r][column];
  }
}

TEST(GuideHapticClient, RendersAForceFromTheRealServer) {
  ServerProcess server(kTcpOnly);
  const ProgramResult r = run_program({PALPATE_HAPTIC_CLIENT_BIN, "--connect", server.address(), "--scene",
                                       "palpation_block", "--seconds", "1"}, limit(60));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const double peak = number_after(r.out, "peak rendered force ");
  EXPECT_GT(peak, 0.0) << r.out;
  EXPECT_LE(peak, 3.3) << "saturated at the device's force limit";
  EXPECT_TRUE(std::regex_search(r.out, std::regex(R"(\d+ setPosition sent, \d+ frames received)"))) << r.out;
}

// The guide's secured set-up: a self-signed certificate and an access token, made with the
// openssl commands docs/guide/haptic-device.md shows; without the token the server refuses.
TEST(GuideHapticClient, ConnectsOverTlsWithAnAccessToken) {
  if (access("/usr/bin/openssl", X_OK) != 0) GTEST_SKIP() << "no /usr/bin/openssl (scripts/setup.sh installs it)";
  const TempDir dir;
  const std::string cert = dir.path + "/cert.pem", key = dir.path + "/key.pem", token = dir.path + "/token";
  ASSERT_EQ(run_program({"/usr/bin/openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                         "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", key, "-out", cert, "-days", "30", "-subj",
                         "/CN=localhost", "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1"},
                        limit(30)).status,
            0);
  const ProgramResult rand = run_program({"/usr/bin/openssl", "rand", "-hex", "32"}, limit(30));
  ASSERT_EQ(rand.status, 0);
  std::ofstream(token) << rand.out;
  {
    ServerProcess server({"--tls-cert", cert, "--tls-key", key, "--access-token-file", token});
    // By the name the certificate carries: TLS checks the host name of --connect.
    const std::string address = "localhost:" + std::to_string(server.port());
    const std::vector<std::string> client = {PALPATE_HAPTIC_CLIENT_BIN, "--connect", address, "--tls-ca", cert,
                                             "--seconds", "0.3"};
    std::vector<std::string> with_token = client;
    with_token.insert(with_token.end(), {"--access-token-file", token});
    const ProgramResult r = run_program(with_token, limit(60));
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    EXPECT_GT(number_after(r.out, "peak rendered force "), 0.0) << r.out;
    const ProgramResult refused = run_program(client, limit(60));
    EXPECT_EQ(refused.status, 1) << refused.out;
    EXPECT_NE(refused.err.find("requires an access token"), std::string::npos) << refused.err;
  }
}

TEST(GuideHapticClient, ARefusalIsReportedWithExitStatus1) {
  ServerProcess server(kTcpOnly);
  const ProgramResult r = run_program({PALPATE_HAPTIC_CLIENT_BIN, "--connect", server.address(), "--scene",
                                       "no_such_scene", "--seconds", "0.1"}, limit(60));
  EXPECT_EQ(r.status, 1) << r.out << r.err;
  EXPECT_NE(r.err.find("unknown scene 'no_such_scene'"), std::string::npos) << r.err;
  EXPECT_EQ(run_program({PALPATE_HAPTIC_CLIENT_BIN, "--seconds", "x"}, limit(10)).status, 2);
}

// Every line of code embedding-the-core.md shows (```cpp blocks; "// ..." stands for lines left
// out) is a line of the example, so that the page shows the API as it compiles.
TEST(GuideEmbedCore, TheMarkdownQuotesTheExampleLineByLine) {
  auto trimmed = [](const std::string& line) {
    const auto first = line.find_first_not_of(" \t"), last = line.find_last_not_of(" \t\r");
    return first == std::string::npos ? std::string() : line.substr(first, last - first + 1);
  };
  std::vector<std::string> example;
  std::istringstream source(read_file(kSource + "/examples/embed_core.cpp"));
  for (std::string line; std::getline(source, line);) example.push_back(trimmed(line));
  const std::string markdown = read_file(kSource + "/docs/guide/embedding-the-core.md");
  int quoted = 0;
  for (auto at = markdown.find("\n```cpp\n"); at != std::string::npos; at = markdown.find("\n```cpp\n", at + 1)) {
    std::istringstream block(markdown.substr(at + 8, markdown.find("\n```\n", at + 8) - (at + 8)));
    for (std::string line; std::getline(block, line);) {
      const std::string code = trimmed(line);
      if (code.empty() || code == "// ...") continue;
      ++quoted;
      EXPECT_NE(std::find(example.begin(), example.end(), code), example.end())
          << "docs/guide/embedding-the-core.md shows a line examples/embed_core.cpp does not have: " << code;
    }
  }
  EXPECT_GT(quoted, 10);
}

TEST(GuideEmbedCore, IndentsTheHapticCubeWithinTenPercentOfHertz) {
  const ProgramResult r = run_program(
      {PALPATE_EMBED_CORE_BIN, kSource + "/scenes/hertz_cube_haptic.json", "53.83", "3000"}, limit(120));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const double error = number_after(r.out, "d/d_Hertz - 1 = ");
  EXPECT_LT(std::abs(error), 10.0) << r.out;
  const double contact = number_after(r.out, "contact force ");
  EXPECT_NEAR(contact, 53.83, 0.01 * 53.83) << "at rest the body pushes back with the command\n" << r.out;
}

TEST(GuideEmbedCore, ErrorsNameTheFile) {
  const ProgramResult r = run_program({PALPATE_EMBED_CORE_BIN, kSource + "/scenes/missing.json"}, limit(20));
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("missing.json: cannot read file"), std::string::npos) << r.err;
  EXPECT_EQ(run_program({PALPATE_EMBED_CORE_BIN, "scene.json", "-1"}, limit(20)).status, 2);
}

}  // namespace
}  // namespace palpate
