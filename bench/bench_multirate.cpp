// palpate-bench-multirate: the multirate verification (bench/multirate_study.h).
// Usage: kUsage below (palpate-bench-multirate --help).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/multirate_study.h"
#include "cli/arguments.h"

namespace {

using namespace palpate;

const char* kUsage = R"(usage: palpate-bench-multirate [options]
Multirate haptics, verified: the full model steps at --model-dt while the force is
rendered at --haptic-rate from the newest step's local model (the server's render
tick, server/haptic_loop.h), along the palpation path of palpate-bench-haptic (tool
free in 3-D: press at site A, hold, slide to B, lift, move to C, press, hold, lift).
The truth is the same scene stepped at the haptic rate; the baseline is the zero-order
hold of the coarse steps' forces. Both runs are headless and deterministic. Prints the
force error |F - F_truth| of the local model and of the hold (median, p99, max; N and %
of the run's peak force), overall and per motion, and the wall time of both runs.
  --scene FILE        the scene (default scenes/hertz_cube_graded.json)
  --set KEY=VALUE     override a scene field of both runs (repeatable)
  --haptic-rate HZ    render rate and the truth's step rate, (0, 100000] (default 1000)
  --model-dt S        the full model's step, a whole number of haptic periods (default:
                      the scene's integrator.dt)
  --seconds S         the path's duration, (0, 3600] (default 6)
  --depth M           press depth below first touch, m (default R/5)
  --stiffness-lag N   also render with the contact stiffness of N coarse steps before
                      the step rendered from, as a real-time session's worker lags it
                      (repeatable; each adds a row per motion: "local, K N steps old")
  --touch-lookahead S the coarse run's stiffness at first touch is taken at the depth
                      the tool reaches S/2 later at its approach speed (docs/physics.md
                      (2.22); default 0: at the touch)
  --csv FILE          write every render tick: t, motion, truth, multirate and hold forces
                      (x y z, N), the model's age (s), the lagged renders (x y z, N)
  --json              print one JSON object instead of the table
  --help              print this text and exit
Exit status: 0 when done; 1 when a run fails; 2 for a wrong argument.
)";

struct Stats {
  double median = 0, p99 = 0, max = 0;
};

Stats stats_of(std::vector<double> v) {
  Stats s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  auto at = [&](double q) { return v[std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5))]; };
  s.median = at(0.5);
  s.p99 = at(0.99);
  s.max = v.back();
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  bench::MultirateConfig config;
  config.scene_file = PALPATE_SOURCE_DIR "/scenes/hertz_cube_graded.json";
  std::string csv;
  bool json_out = false;
  try {
    for (cli::Arguments args(argc, argv); args.next();) {
      const std::string& arg = args.flag();
      if (arg == "--scene") config.scene_file = args.value();
      else if (arg == "--set") config.overrides.push_back(cli::scene_override(args.value()));
      else if (arg == "--haptic-rate") config.haptic_rate_hz = args.number(1e-9, 100000);
      else if (arg == "--model-dt") config.model_dt = args.number(1e-9, 10);
      else if (arg == "--seconds") config.seconds = args.number(1e-9, 3600);
      else if (arg == "--depth") config.depth = args.number(1e-12, 1e3);
      else if (arg == "--stiffness-lag") config.stiffness_lags.push_back(static_cast<int>(args.integer(0, 100000)));
      else if (arg == "--touch-lookahead") config.touch_lookahead = args.number(0, 10);
      else if (arg == "--csv") csv = args.value();
      else if (arg == "--json") json_out = true;
      else if (args.help()) {
        std::cout << kUsage;
        return 0;
      } else throw std::invalid_argument("unknown option '" + arg + "'");
    }
  } catch (const std::exception& e) {
    std::cerr << "palpate-bench-multirate: " << e.what() << "\n\n" << kUsage;
    return 2;
  }

  bench::MultirateResult r;
  try {
    r = bench::run_multirate_study(config);
  } catch (const std::exception& e) {
    std::cerr << "palpate-bench-multirate: " << e.what() << "\n";
    return 1;
  }

  // Errors per motion kind (approach, press, hold, slide, lift, move) and overall.
  const int kinds = 6;
  std::vector<std::vector<double>> local(kinds + 1), hold(kinds + 1);
  // By the model's age in render periods: at age 0 the step's state is as new as the truth's,
  // so its error is the coarse step's own (the floor no rendering can remove).
  std::vector<std::vector<double>> local_by_age, hold_by_age;
  std::vector<double> ages;
  for (const auto& s : r.samples) {
    const int kind = static_cast<int>(r.segments[s.segment].motion);
    const double el = (s.multirate - s.truth).norm(), eh = (s.hold - s.truth).norm();
    local[kind].push_back(el);
    hold[kind].push_back(eh);
    local[kinds].push_back(el);
    hold[kinds].push_back(eh);
    ages.push_back(s.model_age);
    const size_t a = static_cast<size_t>(std::lround(s.model_age / r.haptic_dt));
    if (a >= local_by_age.size()) local_by_age.resize(a + 1), hold_by_age.resize(a + 1);
    local_by_age[a].push_back(el);
    hold_by_age[a].push_back(eh);
  }
  // The same with the stiffness older (--stiffness-lag), per lag and motion.
  const size_t lags = config.stiffness_lags.size();
  std::vector<std::vector<std::vector<double>>> lagged(lags, std::vector<std::vector<double>>(kinds + 1));
  for (const auto& s : r.samples) {
    const int kind = static_cast<int>(r.segments[s.segment].motion);
    for (size_t l = 0; l < lags; ++l) {
      const double e = (s.lagged[l] - s.truth).norm();
      lagged[l][kind].push_back(e);
      lagged[l][kinds].push_back(e);
    }
  }
  const Stats age_stats = stats_of(ages);
  nlohmann::json j;
  j["scene"] = std::filesystem::path(config.scene_file).filename().string();
  j["particles"] = r.particles;
  j["model_dt"] = r.model_dt;
  j["haptic_dt"] = r.haptic_dt;
  j["touch_lookahead_s"] = config.touch_lookahead;
  j["peak_force"] = r.peak;
  j["truth_wall_seconds"] = r.truth_seconds;
  j["coarse_wall_seconds"] = r.coarse_seconds;
  j["model_age_s"] = {{"median", age_stats.median}, {"max", age_stats.max}};
  auto row = [&](const std::vector<double>& e) {
    const Stats s = stats_of(e);
    return nlohmann::json{{"median", s.median}, {"p99", s.p99}, {"max", s.max}};
  };
  for (int k = 0; k <= kinds; ++k) {
    if (local[k].empty()) continue;
    const std::string name = k == kinds ? "all" : haptic::motion_name(static_cast<haptic::Motion>(k));
    j["error"][name] = {{"samples", local[k].size()}, {"local_model", row(local[k])}, {"hold", row(hold[k])}};
  }
  for (size_t l = 0; l < lags; ++l)
    for (int k = 0; k <= kinds; ++k)
      if (!lagged[l][k].empty())
        j["error_stiffness_lagged"][std::to_string(config.stiffness_lags[l])]
         [k == kinds ? "all" : haptic::motion_name(static_cast<haptic::Motion>(k))] = row(lagged[l][k]);
  for (size_t a = 0; a < local_by_age.size(); ++a)
    j["error_by_model_age"].push_back({{"age_s", a * r.haptic_dt}, {"samples", local_by_age[a].size()},
                                       {"local_model", row(local_by_age[a])}, {"hold", row(hold_by_age[a])}});

  if (!csv.empty()) {
    std::ofstream out(csv);
    out << "t,motion,truth_x,truth_y,truth_z,multirate_x,multirate_y,multirate_z,hold_x,hold_y,hold_z,model_age";
    for (const int lag : config.stiffness_lags)
      for (const char* a : {"x", "y", "z"}) out << ",lag" << lag << '_' << a;
    out << '\n';
    for (const auto& s : r.samples) {
      out << s.t << ',' << haptic::motion_name(r.segments[s.segment].motion);
      for (const Vec3* v : {&s.truth, &s.multirate, &s.hold})
        for (int a = 0; a < 3; ++a) out << ',' << (*v)[a];
      out << ',' << s.model_age;
      for (const Vec3& v : s.lagged)
        for (int a = 0; a < 3; ++a) out << ',' << v[a];
      out << '\n';
    }
    if (!out) {
      std::cerr << "palpate-bench-multirate: cannot write " << csv << "\n";
      return 1;
    }
  }

  if (json_out) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("%s: %d particles, model step %.4g s, render at %.0f Hz (%.0f renders per step), touch lookahead %g s\n",
              j["scene"].get<std::string>().c_str(), r.particles, r.model_dt, 1.0 / r.haptic_dt,
              r.model_dt / r.haptic_dt, config.touch_lookahead);
  std::printf("peak force %.4g N; model age median %.2f ms, max %.2f ms; wall time: truth %.1f s, coarse %.1f s\n",
              r.peak, 1e3 * age_stats.median, 1e3 * age_stats.max, r.truth_seconds, r.coarse_seconds);
  std::printf("%-9s %7s | %-30s | %-30s\n", "motion", "renders", "local model: median p99 max N (% peak)",
              "hold: median p99 max N (% peak)");
  for (int k = 0; k <= kinds; ++k) {
    if (local[k].empty()) continue;
    const Stats a = stats_of(local[k]), b = stats_of(hold[k]);
    const std::string name = k == kinds ? "all" : haptic::motion_name(static_cast<haptic::Motion>(k));
    const double p = r.peak > 0 ? 100.0 / r.peak : 0.0;
    std::printf("%-9s %7zu | %.3g %.3g %.3g (%.2f %%) | %.3g %.3g %.3g (%.2f %%)\n", name.c_str(), local[k].size(),
                a.median, a.p99, a.max, a.p99 * p, b.median, b.p99, b.max, b.p99 * p);
  }
  for (size_t l = 0; l < lags; ++l) {
    std::printf("local model, its stiffness %d steps old: p99 N (%% peak) per motion:", config.stiffness_lags[l]);
    for (int k = 0; k <= kinds; ++k) {
      if (lagged[l][k].empty()) continue;
      const double p99 = stats_of(lagged[l][k]).p99;
      std::printf(" %s %.3g (%.2f %%)", k == kinds ? "all" : haptic::motion_name(static_cast<haptic::Motion>(k)),
                  p99, r.peak > 0 ? 100.0 * p99 / r.peak : 0.0);
    }
    std::printf("\n");
  }
  std::printf("by the model's age (age 0: the coarse step's own error, the floor):\n");
  for (size_t a = 0; a < local_by_age.size(); ++a) {
    if (local_by_age[a].empty()) continue;
    const Stats x = stats_of(local_by_age[a]), y = stats_of(hold_by_age[a]);
    std::printf("  age %4.1f ms %7zu | %.3g %.3g %.3g | %.3g %.3g %.3g\n", 1e3 * a * r.haptic_dt,
                local_by_age[a].size(), x.median, x.p99, x.max, y.median, y.p99, y.max);
  }
  return 0;
}
