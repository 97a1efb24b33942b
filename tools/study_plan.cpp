#include "tools/study_plan.h"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>

#include "tools/verification_sweep.h"

namespace palpate::tools {

namespace fs = std::filesystem;
using ordered_json = nlohmann::ordered_json;
using pointer = nlohmann::ordered_json::json_pointer;

namespace {

constexpr std::size_t kMaxCases = 1000000;  // a plan larger than this is a mistake, not a study

// "number 3.5", "string \"x\"", "array of 2 elements": what a field held, for messages.
std::string held(const ordered_json& v) {
  if (v.is_array()) return "array of " + std::to_string(v.size()) + (v.size() == 1 ? " element" : " elements");
  if (v.is_object() || v.is_null()) return v.type_name();
  std::string text = v.dump();
  if (text.size() > 40) text = text.substr(0, 37) + "...";
  return std::string(v.type_name()) + " " + text;
}

// The whole file as JSON (objects keep the order of the file), or a PlanError.
ordered_json read_json_file(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw PlanError(file.string(), "", "cannot read file");
  std::stringstream text;
  text << in.rdbuf();
  try {
    return ordered_json::parse(text.str());
  } catch (const nlohmann::json::exception& e) {
    std::string m = e.what();
    if (const auto tag = m.find("] "); m.rfind("[json.exception.", 0) == 0 && tag != std::string::npos) m.erase(0, tag + 2);
    throw PlanError(file.string(), "", "invalid JSON: " + m);
  }
}

double finite_number(const ordered_json& v, const std::string& file, const pointer& at, const std::string& what) {
  if (!v.is_number() || !std::isfinite(v.get<double>()))
    throw PlanError(file, at.to_string(), "must be " + what + ", got " + held(v));
  return v.get<double>();
}

// A non-empty array at `at`, else a PlanError.
const ordered_json& non_empty_array(const ordered_json& v, const std::string& file, const pointer& at,
                                    const std::string& of) {
  if (!v.is_array() || v.empty())
    throw PlanError(file, at.to_string(), "must be a non-empty array of " + of + ", got " + held(v));
  return v;
}

// Text of a value for a table cell or a case's line: strings as they are, numbers in their
// shortest exact form, null as nothing.
std::string value_text(const ordered_json& v) {
  if (v.is_null()) return "";
  if (v.is_string()) return v.get<std::string>();
  if (v.is_number_float()) {
    char buf[64];
    const auto end = std::to_chars(buf, buf + sizeof buf, v.get<double>()).ptr;
    return std::string(buf, end);
  }
  return v.dump();
}

// A CSV field (RFC 4180): quoted when it holds a comma, a quote or a line break.
std::string csv_field(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string out = "\"";
  for (char c : text) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

void write_csv_row(std::ostream& out, const std::vector<std::string>& cells) {
  for (std::size_t i = 0; i < cells.size(); ++i) out << (i ? "," : "") << csv_field(cells[i]);
  out << "\n";
}

// The member `key` of an object, or null.
const ordered_json& member(const ordered_json& object, const char* key) {
  static const ordered_json null_value;
  if (!object.is_object()) return null_value;
  const auto it = object.find(key);
  return it == object.end() ? null_value : *it;
}

// Why the rows that are not "ok" are not: "F = 53.83 N: diverged (...)".
std::string row_failures(const std::vector<SweepRow>& rows) {
  std::string reasons;
  for (const SweepRow& r : rows) {
    if (r.status == "ok") continue;
    std::ostringstream s;
    s << (reasons.empty() ? "" : "; ") << "F = " << r.force << " N: " << r.status;
    if (!r.failure.empty()) s << " (" << r.failure << ")";
    if (r.status == "not at rest") s << " after " << r.steps << " steps";
    reasons += s.str();
  }
  return reasons;
}

}  // namespace

std::size_t StudyPlan::case_count() const {
  std::size_t count = scenes.size();
  for (const PlanOverride& o : overrides) count *= o.values.size();
  return count * std::max<std::size_t>(1, sites.size());
}

StudyPlan load_study_plan(const fs::path& file) {
  const std::string source = file.string();
  const ordered_json root = read_json_file(file);
  if (!root.is_object()) throw PlanError(source, "", "the top-level value must be an object, got " + held(root));
  const pointer top;
  for (const auto& [key, value] : root.items())
    if (key != "name" && key != "scenes" && key != "overrides" && key != "sites" && key != "forces" &&
        key != "reference")
      throw PlanError(source, (top / key).to_string(),
                      "unknown field (a plan has name, scenes, overrides, sites, forces, reference)");
  StudyPlan plan;
  plan.file = file;
  plan.name = file.stem().string();
  plan.scene_dir = file.parent_path();
  if (const auto& name = member(root, "name"); !name.is_null()) {
    if (!name.is_string() || name.get<std::string>().empty())
      throw PlanError(source, "/name", "must be a non-empty string, got " + held(name));
    plan.name = name.get<std::string>();
  }
  const pointer scenes_at = top / "scenes";
  const ordered_json& scenes = non_empty_array(member(root, "scenes"), source, scenes_at, "scene files");
  for (std::size_t i = 0; i < scenes.size(); ++i) {
    if (!scenes[i].is_string() || scenes[i].get<std::string>().empty())
      throw PlanError(source, (scenes_at / i).to_string(), "must be a scene file name, got " + held(scenes[i]));
    plan.scenes.push_back(scenes[i].get<std::string>());
  }
  if (const auto& overrides = member(root, "overrides"); !overrides.is_null()) {
    if (!overrides.is_object())
      throw PlanError(source, "/overrides", "must be an object {\"dotted.field\": [values]}, got " + held(overrides));
    for (const auto& [key, values] : overrides.items()) {
      const pointer at = top / "overrides" / key;
      if (key.empty() || key.front() == '.' || key.back() == '.' || key.find("..") != std::string::npos)
        throw PlanError(source, at.to_string(), "the key must be a dotted scene field such as mls.neighbors");
      non_empty_array(values, source, at, "values (one case each)");
      PlanOverride o{key, {}};
      for (const auto& v : values) o.values.emplace_back(v);
      plan.overrides.push_back(std::move(o));
    }
  }
  if (const auto& sites = member(root, "sites"); !sites.is_null()) {
    const pointer at = top / "sites";
    non_empty_array(sites, source, at, "[x, y] sites (m)");
    for (std::size_t i = 0; i < sites.size(); ++i) {
      if (!sites[i].is_array() || sites[i].size() != 2)
        throw PlanError(source, (at / i).to_string(), "must be [x, y] (m), got " + held(sites[i]));
      plan.sites.push_back({finite_number(sites[i][0], source, at / i / 0, "a number (m)"),
                            finite_number(sites[i][1], source, at / i / 1, "a number (m)")});
    }
  }
  if (const auto& forces = member(root, "forces"); !forces.is_null()) {
    const pointer at = top / "forces";
    non_empty_array(forces, source, at, "forces (N)");
    for (std::size_t i = 0; i < forces.size(); ++i) {
      const double f = finite_number(forces[i], source, at / i, "a positive number (N)");
      if (!(f > 0)) throw PlanError(source, (at / i).to_string(), "must be a positive number (N), got " + held(forces[i]));
      plan.forces.push_back(f);
    }
  }
  if (const auto& reference = member(root, "reference"); !reference.is_null()) {
    if (reference != "stored" && reference != "none")
      throw PlanError(source, "/reference", "must be \"stored\" or \"none\", got " + held(reference));
    plan.stored_reference = reference == "stored";
  }
  // The count, guarded against a product that overflows or is absurd.
  double count = static_cast<double>(plan.scenes.size()) * std::max<std::size_t>(1, plan.sites.size());
  for (const PlanOverride& o : plan.overrides) count *= static_cast<double>(o.values.size());
  if (count > static_cast<double>(kMaxCases))
    throw PlanError(source, "", "the plan has " + value_text(count) + " cases, more than " +
                                    std::to_string(kMaxCases) + ": split it");
  return plan;
}

StudyCase study_case(const StudyPlan& plan, std::size_t index) {
  if (index >= plan.case_count())
    throw std::out_of_range("case " + std::to_string(index) + " of a plan of " + std::to_string(plan.case_count()) +
                            " cases (0 ... " + std::to_string(plan.case_count() - 1) + ")");
  StudyCase c;
  c.index = index;
  // Mixed radix, the last dimension fastest: sites, then the overrides from the last up, then scenes.
  std::size_t rest = index;
  if (!plan.sites.empty()) {
    c.site_index = rest % plan.sites.size();
    c.site = plan.sites[c.site_index];
    rest /= plan.sites.size();
  }
  c.overrides.resize(plan.overrides.size());
  for (std::size_t k = plan.overrides.size(); k-- > 0;) {
    const PlanOverride& o = plan.overrides[k];
    c.overrides[k] = {o.key, o.values[rest % o.values.size()]};
    rest /= o.values.size();
  }
  c.scene = plan.scenes[rest];
  const fs::path scene(c.scene);
  c.scene_path = scene.is_absolute() ? scene : plan.scene_dir / scene;
  return c;
}

ordered_json case_parameters(const StudyCase& c) {
  ordered_json overrides = ordered_json::object();
  for (const auto& [key, value] : c.overrides) overrides[key] = value;
  ordered_json out;
  out["index"] = c.index;
  out["scene"] = c.scene;
  out["overrides"] = overrides;
  out["site"] = c.site ? ordered_json{(*c.site)[0], (*c.site)[1]} : ordered_json(nullptr);
  return out;
}

std::string describe_case(const StudyCase& c) {
  std::string line = c.scene;
  for (const auto& [key, value] : c.overrides) line += " " + key + "=" + value_text(value);
  if (c.site) line += " site=" + value_text((*c.site)[0]) + "," + value_text((*c.site)[1]);
  return line;
}

ordered_json run_study_case(const StudyPlan& plan, const StudyCase& c, bool quiet) {
  using clock = std::chrono::steady_clock;
  const auto start = clock::now();
  ordered_json result;
  result["plan"] = plan.name;
  result["case"] = case_parameters(c);
  result["status"] = "failed";
  result["reason"] = "";
  result["verification"] = nullptr;
  ordered_json timing;
  try {
    SweepRequest request;
    request.scene_file = c.scene_path.string();
    // Each value as its JSON text: the scene reader reads it back as that very value.
    for (const auto& [key, value] : c.overrides) request.overrides.emplace_back(key, value.dump());
    request.site = c.site;
    request.site_origin = plan.file.string() + ": /sites/" + std::to_string(c.site_index);
    request.forces = plan.forces;
    request.reference = plan.stored_reference ? "auto" : "none";
    const PreparedSweep sweep = prepare_sweep(request);
    const double build_seconds = std::chrono::duration<double>(clock::now() - start).count();
    SweepObserver observer;
    if (!quiet)
      observer.after_force = [&](std::size_t k, const SweepRow& row, const State&) {
        std::fprintf(stderr, "palpate-study: case %zu [%zu/%zu] F = %g N  d = %.6g m  %ld steps, %.2f s  %s\n",
                     c.index, k + 1, sweep.forces.size(), row.force, row.d_sim, row.steps, row.wall_seconds,
                     row.status.c_str());
      };
    const std::vector<SweepRow> rows = run_sweep(sweep, observer);
    double sweep_seconds = 0;
    long steps = 0;
    for (const SweepRow& r : rows) sweep_seconds += r.wall_seconds, steps += r.steps;
    result["verification"] = sweep_json(sweep, rows);
    const std::string failures = row_failures(rows);
    result["status"] = failures.empty() ? "ok" : "failed";
    result["reason"] = failures;
    timing["build_seconds"] = build_seconds;
    timing["sweep_seconds"] = sweep_seconds;
    timing["steps"] = steps;
    timing["seconds_per_step"] = steps > 0 ? ordered_json(sweep_seconds / steps) : ordered_json(nullptr);
  } catch (const std::exception& e) {
    result["reason"] = e.what();
  } catch (...) {
    result["reason"] = "an unknown exception";
  }
  timing["wall_seconds"] = std::chrono::duration<double>(clock::now() - start).count();
  result["timing"] = timing;
  return result;
}

fs::path case_file(const fs::path& dir, std::size_t index) { return dir / ("case_" + std::to_string(index) + ".json"); }

void write_case_result(const fs::path& dir, std::size_t index, const ordered_json& result) {
  const fs::path file = case_file(dir, index);
  fs::path temporary = file;
  temporary += ".partial";
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out << result.dump(2) << "\n";
    if (!out.flush()) throw std::runtime_error("cannot write " + temporary.string());
  }
  std::error_code error;
  fs::rename(temporary, file, error);
  if (error) throw std::runtime_error("cannot rename " + temporary.string() + " to " + file.string() + ": " + error.message());
}

MergeReport merge_study(const StudyPlan& plan, const fs::path& dir) {
  MergeReport report;
  std::ofstream table(dir / "study.csv", std::ios::binary | std::ios::trunc);
  std::ofstream timing(dir / "study_timing.csv", std::ios::binary | std::ios::trunc);
  if (!table || !timing) throw std::runtime_error("cannot write " + (dir / "study.csv").string());
  std::vector<std::string> header{"case", "scene"};
  for (const PlanOverride& o : plan.overrides) header.push_back(o.key);
  for (const char* column :
       {"site_x_m", "site_y_m", "particles", "force_N", "d_sim_m", "d_hertz_m", "d_finite_layer_m", "d_reference_m",
        "d_reference_uncertainty_m", "error_hertz", "error_finite_layer", "error_reference", "contact_force_N",
        "steps", "sim_time_s", "row_status", "l2_error_hertz", "l2_error_finite_layer", "l2_error_reference",
        "case_status", "reason"})
    header.push_back(column);
  write_csv_row(table, header);
  write_csv_row(timing, {"case", "force_N", "steps", "wall_s", "case_build_s", "case_sweep_s", "case_steps",
                         "case_wall_s", "case_wall_per_step_s"});

  for (std::size_t i = 0; i < plan.case_count(); ++i) {
    const StudyCase c = study_case(plan, i);
    const fs::path file = case_file(dir, i);
    ordered_json result;
    std::string status, reason;
    if (!fs::exists(file)) {
      report.missing.push_back(i);
      status = "missing";
    } else {
      try {
        result = read_json_file(file);
        if (member(result, "case") != case_parameters(c) || member(result, "plan") != plan.name)
          throw PlanError(file.string(), "/case",
                          "the result of another case or plan (" + member(result, "case").dump() +
                              "), not of case " + std::to_string(i) + " of " + plan.file.string() + ": run it again");
        status = value_text(member(result, "status"));
        reason = value_text(member(result, "reason"));
        if (status != "ok" && status != "failed")
          throw PlanError(file.string(), "/status", "must be \"ok\" or \"failed\", got " + held(member(result, "status")));
      } catch (const std::exception& e) {
        result = nullptr;
        status = "failed";
        reason = e.what();
      }
      if (status != "ok") report.failed.emplace_back(i, reason);
    }
    const ordered_json& verification = member(result, "verification");
    const ordered_json& case_timing = member(result, "timing");
    std::vector<std::string> parameters{std::to_string(i), c.scene};
    for (const auto& [key, value] : c.overrides) parameters.push_back(value_text(value));
    const ordered_json& site = member(verification, "site");
    parameters.push_back(site.is_array() ? value_text(site[0]) : c.site ? value_text((*c.site)[0]) : "");
    parameters.push_back(site.is_array() ? value_text(site[1]) : c.site ? value_text((*c.site)[1]) : "");
    parameters.push_back(value_text(member(verification, "particles")));
    const ordered_json& rows = member(verification, "rows");
    const std::size_t row_count = rows.is_array() ? rows.size() : 0;
    for (std::size_t k = 0; k < std::max<std::size_t>(1, row_count); ++k) {
      const ordered_json& row = k < row_count ? rows[k] : ordered_json();
      std::vector<std::string> cells = parameters;
      for (const char* key : {"force", "d_sim", "d_hertz", "d_finite_layer", "d_reference", "d_reference_uncertainty",
                              "error_hertz", "error_finite_layer", "error_reference", "contact_force", "steps",
                              "sim_time", "status"})
        cells.push_back(value_text(member(row, key)));
      for (const char* key : {"l2_error_hertz", "l2_error_finite_layer", "l2_error_reference"})
        cells.push_back(value_text(member(verification, key)));
      cells.push_back(status);
      cells.push_back(reason);
      write_csv_row(table, cells);
      ++report.rows;
      if (k < row_count)
        write_csv_row(timing, {std::to_string(i), value_text(member(row, "force")), value_text(member(row, "steps")),
                               value_text(member(row, "wall_seconds")), value_text(member(case_timing, "build_seconds")),
                               value_text(member(case_timing, "sweep_seconds")), value_text(member(case_timing, "steps")),
                               value_text(member(case_timing, "wall_seconds")),
                               value_text(member(case_timing, "seconds_per_step"))});
    }
  }
  if (!table.flush() || !timing.flush()) throw std::runtime_error("cannot write the tables in " + dir.string());
  return report;
}

}  // namespace palpate::tools
