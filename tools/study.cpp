// palpate-study: a verification study as a job array (docs/study.md). A plan is the
// product of scenes, scene overrides and sites; each case is one palpate-verify sweep
// (tools/verification_sweep.h) run by one task of a Kubernetes Indexed Job or a Slurm
// array into its own result file, and `merge` gathers the files into one table and the
// accuracy-cost plot.
#include <spawn.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>
#include <spdlog/spdlog.h>
#include <string>
#include <vector>

#include "cli/arguments.h"
#include "tools/study_plan.h"

extern char** environ;

namespace {

using namespace palpate;
namespace fs = std::filesystem;

const char* kUsage = R"(usage: palpate-study PLAN.json --out DIR [--index I | --all] [--scenes DIR] [--quiet]
       palpate-study PLAN.json --list | --count
       palpate-study merge PLAN.json --out DIR [--no-plot]
Runs the cases of a study plan, one verification sweep (palpate-verify) each, and
gathers their results (the plan format, the case order and the files: docs/study.md).
  --scenes DIR  where the plan's relative scene names are found (default: the plan
                file's folder)
  --out DIR     the folder of the result files (created): DIR/case_<I>.json per case
  --index I     run case I (from 0). Default: $JOB_COMPLETION_INDEX (a Kubernetes
                Indexed Job), else $SLURM_ARRAY_TASK_ID (a Slurm array); with neither
                set, --index or --all is required
  --all         run every case in this process, one after the other (the same files)
  --list        print every case with its index (scene, override values, site)
  --count       print the number of cases (a Job's completions, a Slurm array's size)
  --quiet       no progress on stderr
  --log-level LEVEL  spdlog level (default: warn)
merge: reads DIR/case_<I>.json of every case of the plan and writes DIR/study.csv
(one row per case and force: the parameters, the sweep's rows, the L2 errors and the
status; a failed or missing case has one row with its status), DIR/study_timing.csv
(the wall times, which differ from run to run) and DIR/study.png (the accuracy-cost
plot, scripts/plot_study.py with /usr/bin/python3 and matplotlib; --no-plot skips it).
Exit status: 0 every case ran (merge: every case is there and ok); 1 a case failed
(its file says why; merge: cases are missing or failed, the tables are still
written); 2 a wrong argument or a malformed plan (nothing run).
)";

constexpr const char* kProgram = "palpate-study";

// The case index of this task: --index, else the job array's environment variable.
std::size_t task_index(const std::optional<long long>& option, std::size_t count) {
  std::string origin = "--index";
  long long index = 0;
  if (option) {
    index = *option;
  } else {
    const char* variable = nullptr;
    for (const char* name : {"JOB_COMPLETION_INDEX", "SLURM_ARRAY_TASK_ID"})
      if (const char* v = std::getenv(name); v && *v && !variable) variable = name;
    if (!variable)
      throw std::invalid_argument(
          "which case? give --index I (or --all); neither JOB_COMPLETION_INDEX (Kubernetes Indexed Job) nor "
          "SLURM_ARRAY_TASK_ID (Slurm array) is set");
    origin = std::string(variable);
    index = cli::integer(std::getenv(variable), origin);
  }
  if (index < 0 || static_cast<unsigned long long>(index) >= count)
    throw std::invalid_argument(origin + " = " + std::to_string(index) + ": the plan has " + std::to_string(count) +
                                " cases, 0 ... " + std::to_string(count - 1));
  return static_cast<std::size_t>(index);
}

// Runs one case and writes its file; true when it is ok.
bool run_case(const tools::StudyPlan& plan, std::size_t index, const fs::path& out, bool quiet) {
  const tools::StudyCase c = tools::study_case(plan, index);
  if (!quiet) std::fprintf(stderr, "palpate-study: case %zu of %zu: %s\n", index, plan.case_count(), tools::describe_case(c).c_str());
  const nlohmann::ordered_json result = tools::run_study_case(plan, c, quiet);
  tools::write_case_result(out, index, result);
  const bool ok = result["status"] == "ok";
  if (!ok)
    std::fprintf(stderr, "palpate-study: case %zu failed: %s\n", index, result["reason"].get<std::string>().c_str());
  if (!quiet)
    std::fprintf(stderr, "palpate-study: case %zu %s in %.2f s -> %s\n", index, ok ? "ok" : "failed",
                 result["timing"]["wall_seconds"].get<double>(), tools::case_file(out, index).c_str());
  return ok;
}

// scripts/plot_study.py DIR: the accuracy-cost plot. Returns what to say about it.
std::string plot(const fs::path& dir) {
  const fs::path script = fs::path(PALPATE_SOURCE_DIR) / "scripts" / "plot_study.py";
  const std::string python = "/usr/bin/python3";
  if (!fs::exists(python)) return "no plot: " + python + " is missing (apt-get install python3-matplotlib)";
  if (!fs::exists(script)) return "no plot: " + script.string() + " is missing";
  std::vector<std::string> args{python, script.string(), dir.string()};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (posix_spawn(&pid, python.c_str(), nullptr, nullptr, argv.data(), environ) != 0) return "no plot: cannot run " + python;
  int status = 0;
  waitpid(pid, &status, 0);
  const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (code == 0) return "wrote " + (dir / "study.png").string();
  if (code == 4) return "no plot: no case ran to the end";
  if (code == 3) return "no plot: python3-matplotlib is missing (apt-get install python3-matplotlib); the tables are written";
  return "no plot: " + script.string() + " failed (exit status " + std::to_string(code) + ")";
}

std::string index_list(const std::vector<std::size_t>& indices) {
  std::string text;
  for (std::size_t i : indices) text += (text.empty() ? "" : ", ") + std::to_string(i);
  return text;
}

}  // namespace

int main(int argc, char** argv) {
  bool merge = false, all = false, list = false, count = false, quiet = false, no_plot = false;
  std::string plan_file, out_dir, scene_dir, log_level = "warn";
  std::optional<long long> index;
  cli::parse_or_exit(argc, argv, kProgram, kUsage, [&](cli::Arguments& args) {
    const std::string& flag = args.flag();
    if (flag == "--out") out_dir = args.value();
    else if (flag == "--scenes") scene_dir = args.value();
    else if (flag == "--index") index = args.integer(0, 1000000);
    else if (flag == "--all") all = true;
    else if (flag == "--list") list = true;
    else if (flag == "--count") count = true;
    else if (flag == "--quiet") quiet = true;
    else if (flag == "--no-plot") no_plot = true;
    else if (flag == "--log-level") log_level = args.value();
    else if (flag == "merge" && !merge && plan_file.empty()) merge = true;
    else if (!flag.empty() && flag[0] != '-' && plan_file.empty()) plan_file = flag;
    else return false;
    return true;
  });
  if (plan_file.empty()) cli::usage_error(kProgram, "PLAN.json is required", kUsage);
  const int modes = int(all) + int(list) + int(count) + int(index.has_value()) + int(merge);
  if (modes > 1) cli::usage_error(kProgram, "merge, --index, --all, --list and --count exclude each other", kUsage);
  if (!list && !count && out_dir.empty()) cli::usage_error(kProgram, "--out DIR is required", kUsage);
  spdlog::set_level(spdlog::level::from_str(log_level));

  std::optional<tools::StudyPlan> plan;
  try {
    plan = tools::load_study_plan(plan_file);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", kProgram, e.what());
    return 2;
  }
  if (!scene_dir.empty()) plan->scene_dir = scene_dir;
  const std::size_t cases = plan->case_count();
  if (count) {
    std::printf("%zu\n", cases);
    return 0;
  }
  if (list) {
    for (std::size_t i = 0; i < cases; ++i) std::printf("%zu\t%s\n", i, tools::describe_case(tools::study_case(*plan, i)).c_str());
    return 0;
  }

  try {
    fs::create_directories(out_dir);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: --out %s: %s\n", kProgram, out_dir.c_str(), e.what());
    return 2;
  }

  if (merge) {
    tools::MergeReport report;
    try {
      report = tools::merge_study(*plan, out_dir);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "%s: merge: %s\n", kProgram, e.what());
      return 1;
    }
    std::fprintf(stderr, "%s: %zu cases, %zu rows -> %s, %s\n", kProgram, cases, report.rows,
                 (fs::path(out_dir) / "study.csv").c_str(), (fs::path(out_dir) / "study_timing.csv").c_str());
    if (!report.missing.empty())
      std::fprintf(stderr, "%s: missing: %zu of %zu cases have no result file: %s (run them with --index I)\n", kProgram,
                   report.missing.size(), cases, index_list(report.missing).c_str());
    if (!report.failed.empty()) {
      std::vector<std::size_t> failed;
      for (const auto& [i, reason] : report.failed) failed.push_back(i);
      std::fprintf(stderr, "%s: failed: %zu of %zu cases: %s\n", kProgram, failed.size(), cases, index_list(failed).c_str());
      for (const auto& [i, reason] : report.failed) std::fprintf(stderr, "  case %zu: %s\n", i, reason.c_str());
    }
    if (!no_plot) std::fprintf(stderr, "%s: %s\n", kProgram, plot(out_dir).c_str());
    return report.missing.empty() && report.failed.empty() ? 0 : 1;
  }

  std::vector<std::size_t> to_run;
  if (all) {
    for (std::size_t i = 0; i < cases; ++i) to_run.push_back(i);
  } else {
    try {
      to_run.push_back(task_index(index, cases));
    } catch (const std::exception& e) {
      cli::usage_error(kProgram, e.what(), kUsage);
    }
  }
  std::vector<std::size_t> failed;
  for (std::size_t i : to_run) {
    try {
      if (!run_case(*plan, i, out_dir, quiet)) failed.push_back(i);
    } catch (const std::exception& e) {  // the result file could not be written
      std::fprintf(stderr, "%s: case %zu: %s\n", kProgram, i, e.what());
      failed.push_back(i);
    }
  }
  if (all && !failed.empty())
    std::fprintf(stderr, "%s: %zu of %zu cases failed: %s\n", kProgram, failed.size(), cases, index_list(failed).c_str());
  return failed.empty() ? 0 : 1;
}
