#pragma once
// Studies as job arrays (docs/study.md): a plan is the Cartesian product of scenes,
// scene overrides and sites; each case is one verification sweep (tools/verification_sweep.h)
// run on its own (a Kubernetes Indexed Job's or a Slurm array's task) into its own result
// file, and the merge gathers the files into one table.
#include <array>
#include <cstddef>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace palpate::tools {

// A malformed plan or result file. what(): "FILE: /json/pointer: reason" (the field is
// left out when the whole file is at fault), as core's SceneError.
class PlanError : public std::runtime_error {
 public:
  PlanError(const std::string& file, const std::string& field, const std::string& reason)
      : std::runtime_error(file + ": " + (field.empty() ? std::string() : field + ": ") + reason) {}
};

// One field the plan varies: the dotted scene path (as --set takes it) and its values.
struct PlanOverride {
  std::string key;
  std::vector<nlohmann::json> values;
};

struct StudyPlan {
  std::filesystem::path file;  // the plan file as given
  std::string name;            // "name", else the file's stem
  std::vector<std::string> scenes;  // as written in the plan
  std::vector<PlanOverride> overrides;  // in the order of the plan file
  std::vector<std::array<double, 2>> sites;  // m; empty: each scene's own site
  std::vector<double> forces;  // N; empty: each scene's verify.forces
  bool stored_reference = true;  // "reference": "stored" (default) or "none"
  // Where relative scene names are found: the plan file's folder, unless the caller
  // says otherwise (palpate-study --scenes DIR).
  std::filesystem::path scene_dir;

  std::size_t case_count() const;
};

// One case: a scene, one value of each override, a site.
struct StudyCase {
  std::size_t index = 0;
  std::string scene;                 // as written in the plan
  std::filesystem::path scene_path;  // relative names resolved against the plan's scene_dir
  std::vector<std::pair<std::string, nlohmann::json>> overrides;  // (key, value), the plan's order
  std::optional<std::array<double, 2>> site;
  std::size_t site_index = 0;        // the site's position in the plan's "sites"
};

// Reads and validates a plan (throws PlanError naming the file, the field and the reason).
// Only the plan's own shape is checked here; each case's scene is validated when it runs.
StudyPlan load_study_plan(const std::filesystem::path& file);

// The case with this index (< case_count()). The order: scenes outermost, then the
// overrides in the order the plan lists them, sites innermost; the last varies fastest.
StudyCase study_case(const StudyPlan& plan, std::size_t index);

// The case's parameters as JSON: {"index", "scene", "overrides": {key: value, ...}, "site"}.
nlohmann::ordered_json case_parameters(const StudyCase& c);

// One line: "scenes/a.json mls.neighbors=16 material.young_modulus=10000 site=0.4,0.3".
std::string describe_case(const StudyCase& c);

// Runs one case (the verification sweep of its scene) and returns its result document
// (docs/study.md, "Result files"). Never throws: a case that cannot run has "status":
// "failed" and the reason. `quiet`: no progress on stderr.
nlohmann::ordered_json run_study_case(const StudyPlan& plan, const StudyCase& c, bool quiet);

// DIR/case_<index>.json.
std::filesystem::path case_file(const std::filesystem::path& dir, std::size_t index);

// Writes the result document to case_file(dir, index) through a temporary file and a
// rename, so that a reader never sees half a file (throws std::runtime_error).
void write_case_result(const std::filesystem::path& dir, std::size_t index, const nlohmann::ordered_json& result);

// What the merge found.
struct MergeReport {
  std::vector<std::size_t> missing;  // no result file
  std::vector<std::pair<std::size_t, std::string>> failed;  // (index, reason): failed, unreadable or of another plan
  std::size_t rows = 0;              // rows written to study.csv
};

// Gathers DIR/case_<I>.json of every case of the plan into DIR/study.csv (one row per case
// and force: the parameters and the results; a failed or missing case has one row with its
// status) and DIR/study_timing.csv (the wall times, apart: they differ from run to run).
// Throws std::runtime_error when a file cannot be written.
MergeReport merge_study(const StudyPlan& plan, const std::filesystem::path& dir);

}  // namespace palpate::tools
