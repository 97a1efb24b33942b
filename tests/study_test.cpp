// palpate-study (docs/study.md) as a job array runs it: a four-case plan run as four
// processes (two of them told their case by JOB_COMPLETION_INDEX and SLURM_ARRAY_TASK_ID)
// merges to the same table as one process running all four; a case that fails and cases
// that never ran are named by the merge; a result file of another case is refused; the
// case order and the plan's errors; deploy/study.sbatch with a stand-in for sbatch. The cases are tiny (9^3 particles, two forces).
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cli/child_process.h"

namespace fs = std::filesystem;

namespace palpate {
namespace {

using cli::ProgramResult;
using cli::run_program;

constexpr auto kTimeout = std::chrono::seconds(300);  // a sanitized build steps ~10x slower

std::string read_text(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// CSV text as rows of fields (the test's tables hold no quoted commas but the reasons,
// which are compared as text).
std::vector<std::vector<std::string>> csv_rows(const std::string& text) {
  std::vector<std::vector<std::string>> rows;
  std::stringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    std::vector<std::string> fields;
    std::stringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) fields.push_back(cell);
    if (!line.empty() && line.back() == ',') fields.emplace_back();
    rows.push_back(fields);
  }
  return rows;
}

std::size_t column(const std::vector<std::string>& header, const std::string& name) {
  for (std::size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return i;
  ADD_FAILURE() << "no column " << name;
  return 0;
}

class StudyTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("palpate_study_test_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    unsetenv("JOB_COMPLETION_INDEX");
    unsetenv("SLURM_ARRAY_TASK_ID");
    if (const char* path = std::getenv("PATH")) path_ = path;
  }
  void TearDown() override {
    if (!path_.empty()) setenv("PATH", path_.c_str(), 1);
    unsetenv("PALPATE_BIN");
    unsetenv("JOB_COMPLETION_INDEX");
    unsetenv("SLURM_ARRAY_TASK_ID");
    if (!HasFailure()) fs::remove_all(dir_);
  }

  // A plan in the test's folder; its scenes are the repository's (their stored references apply).
  fs::path write_plan(const std::string& name, const std::string& text) {
    const fs::path file = dir_ / name;
    std::ofstream(file) << text;
    return file;
  }

  static ProgramResult study(std::vector<std::string> args) {
    args.insert(args.begin(), PALPATE_STUDY_BIN);
    args.push_back("--scenes");
    args.push_back(std::string(PALPATE_SOURCE_DIR) + "/scenes");
    return run_program(args, kTimeout);
  }

  fs::path dir_;
  std::string path_;  // PATH as the test found it
};

// The default cube at 9^3 (729 particles, one on the axis), two forces of the stored reference's sweep;
// k and E varied: four cases, two of them (E = 10 kPa) with the stored reference.
constexpr const char* kFourCasePlan = R"({
  "name": "four_cases",
  "scenes": ["hertz_cube.json"],
  "overrides": {"body.distribution.per_edge": [9], "mls.neighbors": [16, 26], "material.young_modulus": [1e4, 2e4]},
  "forces": [10.36, 53.83]
})";

TEST_F(StudyTest, FourProcessesMergeToTheTableOfOneProcessRunningAll) {
  const fs::path plan = write_plan("plan.json", kFourCasePlan);
  const ProgramResult count = study({plan, "--count"});
  ASSERT_EQ(count.status, 0) << count.err;
  EXPECT_EQ(count.out, "4\n");

  // Four processes, as four tasks of a job array: two told by --index, one by each variable.
  const fs::path tasks = dir_ / "tasks", single = dir_ / "single";
  for (int index : {0, 1}) {
    const ProgramResult r = study({plan, "--index", std::to_string(index), "--out", tasks, "--quiet"});
    ASSERT_EQ(r.status, 0) << r.err;
  }
  setenv("JOB_COMPLETION_INDEX", "2", 1);
  ProgramResult r = study({plan, "--out", tasks, "--quiet"});
  ASSERT_EQ(r.status, 0) << r.err;
  unsetenv("JOB_COMPLETION_INDEX");
  EXPECT_FALSE(fs::exists(tasks / "case_3.json")) << "JOB_COMPLETION_INDEX=2 ran another case";
  setenv("SLURM_ARRAY_TASK_ID", "3", 1);
  r = study({plan, "--out", tasks, "--quiet"});
  ASSERT_EQ(r.status, 0) << r.err;
  unsetenv("SLURM_ARRAY_TASK_ID");
  for (int index = 0; index < 4; ++index) {
    const auto result = nlohmann::json::parse(read_text(tasks / ("case_" + std::to_string(index) + ".json")));
    EXPECT_EQ(result["case"]["index"], index);
    EXPECT_EQ(result["status"], "ok") << result["reason"];
    EXPECT_EQ(result["verification"]["particles"], 729);
    EXPECT_GT(result["timing"]["seconds_per_step"].get<double>(), 0);
  }

  // One process running all four.
  r = study({plan, "--all", "--out", single, "--quiet"});
  ASSERT_EQ(r.status, 0) << r.err;

  for (const fs::path& out : {tasks, single}) {
    r = study({"merge", plan, "--out", out});
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.err.find("4 cases, 8 rows"), std::string::npos) << r.err;
  }
  const std::string table = read_text(tasks / "study.csv");
  EXPECT_EQ(table, read_text(single / "study.csv")) << "the four processes' table differs from the single run's";

  // The table is the plan's product with the results in it: the overrides took effect, the
  // stored reference applies to E = 10 kPa only, every row is at rest.
  const auto rows = csv_rows(table);
  ASSERT_EQ(rows.size(), 9u) << table;
  const auto& header = rows[0];
  const std::size_t k = column(header, "mls.neighbors"), E = column(header, "material.young_modulus"),
                    force = column(header, "force_N"), d_sim = column(header, "d_sim_m"),
                    d_ref = column(header, "d_reference_m"), status = column(header, "case_status"),
                    row_status = column(header, "row_status");
  const std::vector<std::pair<std::string, std::string>> expected{{"16", "10000"}, {"16", "20000"}, {"26", "10000"},
                                                                  {"26", "20000"}};
  for (std::size_t c = 0; c < 4; ++c)
    for (std::size_t f = 0; f < 2; ++f) {
      const auto& row = rows[1 + 2 * c + f];
      EXPECT_EQ(row[0], std::to_string(c));
      EXPECT_EQ(row[k], expected[c].first);
      EXPECT_EQ(row[E], expected[c].second);
      EXPECT_EQ(row[force], f == 0 ? "10.36" : "53.83");
      EXPECT_EQ(row[status], "ok");
      EXPECT_EQ(row[row_status], "ok");
      EXPECT_EQ(row[d_ref].empty(), expected[c].second != "10000") << "case " << c;
      EXPECT_GT(std::stod(row[d_sim]), 0);
    }
  for (std::size_t c : {0, 2}) {  // twice as stiff: between 1/2 (one particle under the tool) and Hertz's 2^(-2/3) as deep
    const double ratio = std::stod(rows[1 + 2 * (c + 1) + 1][d_sim]) / std::stod(rows[1 + 2 * c + 1][d_sim]);
    EXPECT_GT(ratio, 0.45) << "case " << c;
    EXPECT_LT(ratio, 0.68) << "case " << c;
  }

  // The wall times are in their own table, one row per case and force.
  const auto timing = csv_rows(read_text(single / "study_timing.csv"));
  ASSERT_EQ(timing.size(), 9u);
  EXPECT_EQ(timing[0][column(timing[0], "case_wall_per_step_s")], "case_wall_per_step_s");
}

// deploy/study.sbatch against a stand-in for sbatch that records its arguments: the array
// of the plan's size, the merge after it (afterany); then its tasks and its merge run as
// Slurm would run them.
TEST_F(StudyTest, SlurmScriptSubmitsTheArrayAndTheMergeAndRunsThem) {
  const fs::path plan = write_plan("plan.json", R"({
    "scenes": ["hertz_cube.json"],
    "overrides": {"body.distribution.per_edge": [9], "mls.neighbors": [16, 26]},
    "forces": [10.36]
  })");
  const fs::path log = dir_ / "sbatch.log", fake = dir_ / "bin" / "sbatch", out = dir_ / "out";
  fs::create_directories(fake.parent_path());
  std::ofstream(fake) << "#!/bin/sh\necho \"$@\" >> '" << log.string() << "'\necho \"$((1000 + $(wc -l < '"
                      << log.string() << "')));cluster\"\n";
  fs::permissions(fake, fs::perms::owner_all);
  const std::string script = std::string(PALPATE_SOURCE_DIR) + "/deploy/study.sbatch";
  const std::string scenes = std::string(PALPATE_SOURCE_DIR) + "/scenes";
  setenv("PALPATE_BIN", fs::path(PALPATE_STUDY_BIN).parent_path().c_str(), 1);
  setenv("PATH", (fake.parent_path().string() + ":" + std::getenv("PATH")).c_str(), 1);
  ProgramResult r = run_program({"/bin/bash", script, plan, out, scenes}, kTimeout);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("2 cases: array job 1001 (tasks 0-1), merge job 1002"), std::string::npos) << r.out;
  std::stringstream calls(read_text(log));
  std::string array_call, merge_call;
  std::getline(calls, array_call);
  std::getline(calls, merge_call);
  EXPECT_EQ(array_call, "--parsable --array=0-1 " + script + " " + plan.string() + " " + out.string() + " " + scenes);
  EXPECT_NE(merge_call.find("--dependency=afterany:1001 "), std::string::npos) << merge_call;
  EXPECT_NE(merge_call.find("--export=ALL,PALPATE_STUDY_STAGE=merge " + script + " "), std::string::npos) << merge_call;

  for (const char* task : {"0", "1"}) {
    setenv("SLURM_ARRAY_TASK_ID", task, 1);
    r = run_program({"/bin/bash", script, plan, out, scenes}, kTimeout);
    ASSERT_EQ(r.status, 0) << r.err;
  }
  unsetenv("SLURM_ARRAY_TASK_ID");
  setenv("PALPATE_STUDY_STAGE", "merge", 1);
  r = run_program({"/bin/bash", script, plan, out, scenes}, kTimeout);
  unsetenv("PALPATE_STUDY_STAGE");
  EXPECT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("2 cases, 2 rows"), std::string::npos) << r.err;
}

TEST_F(StudyTest, FailedAndMissingCasesAreNamedByTheMerge) {
  // Three cases; case 1's Poisson ratio is out of range; cases 0 and 2 never run.
  const fs::path plan = write_plan("plan.json", R"({
    "scenes": ["hertz_cube.json"],
    "overrides": {"material.poisson_ratio": [0.3, 0.7, 0.45]}
  })");
  const fs::path out = dir_ / "out";
  ProgramResult r = study({plan, "--index", "1", "--out", out});
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("case 1 failed"), std::string::npos) << r.err;
  const auto result = nlohmann::json::parse(read_text(out / "case_1.json"));
  EXPECT_EQ(result["status"], "failed");
  const std::string reason = result["reason"];
  EXPECT_NE(reason.find("override material.poisson_ratio=0.7"), std::string::npos) << reason;
  EXPECT_NE(reason.find("/material/poisson_ratio: must be a number in (-1, 0.5), got 0.7"), std::string::npos) << reason;

  r = study({"merge", plan, "--out", out, "--no-plot"});
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("missing: 2 of 3 cases have no result file: 0, 2"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("failed: 1 of 3 cases: 1\n  case 1: " + reason), std::string::npos) << r.err;
  const auto rows = csv_rows(read_text(out / "study.csv"));
  ASSERT_EQ(rows.size(), 4u);
  const std::size_t status = column(rows[0], "case_status");
  EXPECT_EQ(rows[1][status], "missing");
  EXPECT_EQ(rows[2][status], "failed");
  EXPECT_EQ(rows[3][status], "missing");

  // A result file of another case (case 1's, copied over case 0's) is not taken for case 0.
  fs::copy_file(out / "case_1.json", out / "case_0.json");
  r = study({"merge", plan, "--out", out, "--no-plot"});
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("case 0: " + (out / "case_0.json").string() + ": /case: the result of another case"),
            std::string::npos)
      << r.err;
}

TEST_F(StudyTest, CaseOrderAndIndexErrors) {
  const fs::path plan = write_plan("plan.json", R"({
    "scenes": ["a.json", "b.json"],
    "overrides": {"mls.neighbors": [16, 26], "material.law": ["corotational", "stvk"]},
    "sites": [[0, 0], [0.4, 0.3]]
  })");
  const ProgramResult list = study({plan, "--list"});
  ASSERT_EQ(list.status, 0) << list.err;
  std::stringstream lines(list.out);
  std::vector<std::string> cases;
  for (std::string line; std::getline(lines, line);) cases.push_back(line);
  ASSERT_EQ(cases.size(), 16u) << list.out;
  EXPECT_EQ(cases[0], "0\ta.json mls.neighbors=16 material.law=corotational site=0,0");
  EXPECT_EQ(cases[1], "1\ta.json mls.neighbors=16 material.law=corotational site=0.4,0.3");
  EXPECT_EQ(cases[2], "2\ta.json mls.neighbors=16 material.law=stvk site=0,0");
  EXPECT_EQ(cases[4], "4\ta.json mls.neighbors=26 material.law=corotational site=0,0");
  EXPECT_EQ(cases[15], "15\tb.json mls.neighbors=26 material.law=stvk site=0.4,0.3");

  // No index: a clear error, nothing run.
  ProgramResult r = study({plan, "--out", dir_ / "out"});
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("neither JOB_COMPLETION_INDEX (Kubernetes Indexed Job) nor SLURM_ARRAY_TASK_ID"),
            std::string::npos)
      << r.err;
  setenv("SLURM_ARRAY_TASK_ID", "16", 1);
  r = study({plan, "--out", dir_ / "out"});
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("SLURM_ARRAY_TASK_ID = 16: the plan has 16 cases, 0 ... 15"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "out" / "case_16.json"));
}

TEST_F(StudyTest, PlanErrorsNameTheFileTheFieldAndTheReason) {
  const std::vector<std::pair<std::string, std::string>> cases{
      {R"({"scenes": []})", "/scenes: must be a non-empty array of scene files, got array of 0 elements"},
      {R"({"scenes": ["a.json"], "overrides": {"mls.neighbors": 16}})",
       "/overrides/mls.neighbors: must be a non-empty array of values (one case each), got number 16"},
      {R"({"scenes": ["a.json"], "sites": [[0, 0], [0.4]]})", "/sites/1: must be [x, y] (m), got array of 1 element"},
      {R"({"scenes": ["a.json"], "forces": [10, -1]})", "/forces/1: must be a positive number (N), got number -1"},
      {R"({"scenes": ["a.json"], "reference": "compute"})", "/reference: must be \"stored\" or \"none\""},
      {R"({"scenes": ["a.json"], "sweeps": []})", "/sweeps: unknown field"},
      {R"({"scenes": ["a.json"],})", "invalid JSON"},
  };
  for (const auto& [text, message] : cases) {
    const fs::path plan = write_plan("bad.json", text);
    const ProgramResult r = study({plan, "--count"});
    EXPECT_EQ(r.status, 2) << text;
    EXPECT_NE(r.err.find(plan.string() + ": " + message), std::string::npos) << text << "\n" << r.err;
  }
}

}  // namespace
}  // namespace palpate
