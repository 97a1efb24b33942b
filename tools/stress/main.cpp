// palpate-stress: the stable envelope of the models and integrators and the
// stress studies of issue #7 (docs/stability.md):
//   envelope     the largest stable dt by bisection (analysis/stability.h) per model,
//                integrator, cloud and damping, against dt = c dx_min / c_p;
//   large_force  forces far beyond the Hertz sweep, sudden steps, a reversal;
//   inversion    compression to inversion, release with and without k_v;
//   zero_energy  checkerboard and velocity noise with and without hourglass control;
//   long_run     10^6 steps under a periodic force command.
// One file per study (studies.h) over a shared harness (harness.h); this file parses
// the arguments, runs the studies asked for and writes the output.
// Progress on stderr; --json prints one object on stdout; --out DIR writes CSV files
// and runs scripts/plot_stability.py (Debian's /usr/bin/python3) for the PNG figures.
#include <exception>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>

#include "cli/arguments.h"
#include "tools/stress/harness.h"
#include "tools/stress/studies.h"

namespace {

using namespace palpate;
using namespace palpate::stress;

const char* kUsage = R"(usage: palpate-stress [options]
Maps the stable envelope and runs the stress studies (docs/stability.md).
  --quick           the two-minute version: 10^3 uniform and 11^3 graded clouds, the
                    scenes' damping only, a coarser bisection, 10^4 long-run steps
  --smoke           a few seconds: 6^3 / 7^3 clouds, short runs (checks the pipeline)
  --only LIST       comma-separated studies: envelope,large_force,inversion,zero_energy,long_run
  --long-steps N    steps of the long run (default 10^6; --quick 10^4; --smoke 500)
  --graded-implicit also map implicit Euler on the graded clouds (off by default: one
                    200-step trial costs minutes there: a CG solve per contact candidate
                    on a lattice with spacings from 0.025 m to ~0.2 m)
  --scenes DIR      folder of the default scenes (default: the source tree's scenes/)
  --json            print one JSON object on stdout (progress stays on stderr)
  --out DIR         write CSV files and the JSON there, then scripts/plot_stability.py
                    makes the PNG figures (needs /usr/bin/python3 with matplotlib)
  --raw DIR         with --out: stress.json goes to DIR instead (the repository keeps
                    it under data/stability/, data/README.md)
  --quiet           no progress on stderr
)";

}  // namespace

int main(int argc, char** argv) {
  StressOptions stress;
  try {
    for (cli::Arguments args(argc, argv); args.next();) {
      const std::string& arg = args.flag();
      auto value = [&] { return args.value(); };
      if (arg == "--quick") stress.mode = Mode::quick;
      else if (arg == "--smoke") stress.mode = Mode::smoke;
      else if (arg == "--only") {
        std::stringstream ss(value());
        std::string item;
        while (std::getline(ss, item, ',')) {
          if (item != "envelope" && item != "large_force" && item != "inversion" && item != "zero_energy" && item != "long_run")
            throw std::invalid_argument("--only: unknown study '" + item + "'");
          stress.only.push_back(item);
        }
      } else if (arg == "--long-steps") stress.long_steps = cli::positive_list<long long>(value(), arg).at(0);
      else if (arg == "--scenes") stress.scenes = value();
      else if (arg == "--json") stress.json = true;
      else if (arg == "--graded-implicit") stress.graded_implicit = true;
      else if (arg == "--out") stress.out = value();
      else if (arg == "--raw") stress.raw = value();
      else if (arg == "--quiet") stress.quiet = true;
      else if (arg == "--help" || arg == "-h") {
        std::cout << kUsage;
        return 0;
      } else throw std::invalid_argument("unknown option '" + arg + "'");
    }
  } catch (const std::exception& e) {
    std::cerr << "palpate-stress: " << e.what() << "\n\n" << kUsage;
    return 2;
  }
  set_quiet(stress.quiet);
  const char* mode = stress.mode == Mode::full ? "full" : stress.mode == Mode::quick ? "quick" : "smoke";
  json result, meta, zero_series = json::array(), zero_ratios = json::array(), long_periods = json::array();
  result["tool"] = "palpate-stress";
  result["mode"] = mode;
  result["clouds"] = stress.mode == Mode::full ? "the default scenes: uniform 18^3 and graded 21^3"
                     : stress.mode == Mode::quick
                         ? "--quick: the default scenes resized to uniform 10^3 and graded 11^3 (not the default clouds)"
                         : "--smoke: uniform 6^3 and graded 7^3 (a pipeline check, not results)";
  try {
    if (stress.wants("envelope")) result["envelope"] = envelope_study(stress, meta);
    if (stress.wants("large_force")) result["large_force"] = large_force_study(stress, meta);
    if (stress.wants("inversion")) result["inversion"] = inversion_study(stress, meta);
    if (stress.wants("zero_energy")) {
      result["zero_energy"] = zero_energy_study(stress, meta, zero_series, zero_ratios);
      result["zero_energy_ratios"] = zero_ratios;
    }
    if (stress.wants("long_run")) result["long_run"] = long_run_study(stress, meta, long_periods);
  } catch (const std::exception& e) {
    std::cerr << "palpate-stress: " << e.what() << "\n";
    return 1;
  }
  result["definitions"] = meta;
  result["wall_seconds"] = seconds_since_start();

  if (!stress.out.empty()) write_out_dir(stress.out, stress.raw, result, zero_series, zero_ratios, long_periods);
  if (stress.json) std::cout << result.dump(2) << "\n";
  else if (stress.out.empty()) std::cout << result.dump(2) << "\n";
  return 0;
}
