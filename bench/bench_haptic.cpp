// palpate-bench-haptic: the haptic client loop against palpate-server (issue #13).
// Usage: kUsage below (palpate-bench-haptic --help).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <capnp/ez-rpc.h>
#include <kj/async-io.h>

#include "cli/arguments.h"
#include "cli/child_process.h"
#include "cli/statistics.h"
#include "bench/multirate_study.h"
#include "clients/haptic.h"
#include "core/scene.h"
#include "protocol/palpate.capnp.h"

namespace {

namespace fs = std::filesystem;
using palpate::wire::PalpateServer;

const char* kUsage = R"(usage: palpate-bench-haptic [options]
The haptic client loop of palpate-client --haptic-rate (clients/haptic.h) as a
benchmark. Starts the server (palpate-server next to this executable, on a loopback
port the system picks, serving --scene at --rate) unless --connect is given, opens a
real-time session with the tool free in 3-D (indenter.guide=free unless --set names
the guide), subscribes to every tick and, for --seconds, moves the device along the
palpation path (above site A, press --depth below first touch, hold, slide to B, lift,
move in the air to C, press, hold, lift) with one setPosition per tick, pipelined,
while a servo loop at --haptic-rate renders the newest frame's local model. Prints:
command-to-force latency (setPosition to the first frame whose commandSeq includes it,
ms), the server's tick lateness, deadline misses, skipped ticks and blow-ups, and the
rendering error at each frame (its render force against the previous frame's local
model at its target, and against the zero-order hold: median / p99 / max in N and in %
of the run's peak force), overall and per segment. --repeat N runs N sessions one
after the other and prints each run's tail figures (lateness p99, misses) and their
median: tail figures swing on a shared machine.
  --json               print one JSON object instead of the table
  --seconds S          length of each run (the path's duration), (0, 86400] (default 10)
  --haptic-rate HZ     the servo loop's rate, (0, 100000] (default 4000)
  --repeat N           sessions run one after the other, [1, 100] (default 1)
  --scene FILE         the scene, served as the server's default scene (default:
                       scenes/palpation_block.json of the source tree if it exists, else
                       scenes/hertz_cube_haptic.json; ignored with --connect, where the
                       server's default scene is used)
  --rate HZ            the server loop's rate, (0, 10000] (default 1000)
  --set KEY=VALUE      override a scene field of the session (repeatable)
  --server-haptic-rate HZ  multirate (OpenRequest.hapticRateHz): the server renders
                       the force at this rate from the newest step's local model while
                       the model steps at --rate; the client sends a setPosition per
                       render tick. 0 = off (default)
  --replay-truth       with --server-haptic-rate: after each run, replay the served
                       forces' device positions, render tick by render tick, into the
                       same scene stepped at the render rate (integrator.dt = 1 / rate,
                       in process, headless) and print |served - truth| per segment:
                       the real-time multirate force against full steps every tick
  --depth M            device depth below first touch, m, > 0 (default R/5)
  --device-stiffness K the device's largest stiffness, N/m, >= 0 (default 0: none)
  --device-damping B   the device's largest damping, N s/m, >= 0 (default 0: none)
  --device-force F     the device's largest force, N, >= 0 (default 0: none)
  --connect ADDR:PORT  use this running server instead of starting one
  --server PATH        the server executable to start (default: palpate-server next to
                       this executable)
  --help               print this text and exit
Exit status: 0 when done; 1 when the server does not start, the connection fails or the
server refuses; 2 for a wrong argument.
)";

std::string default_scene() {
  const std::string block = PALPATE_SOURCE_DIR "/scenes/palpation_block.json";
  return fs::exists(block) ? block : PALPATE_SOURCE_DIR "/scenes/hertz_cube_haptic.json";
}

struct Args {
  bool json = false;
  double seconds = 10.0;
  int repeat = 1;
  std::string scene = default_scene();
  double rate = 1000.0;
  double server_haptic_rate = 0.0;
  bool replay_truth = false;
  std::vector<std::string> overrides;
  palpate::haptic::DeviceFlags haptic{4000.0};
  std::string connect;
  std::string server;
};

Args parse_args(int argc, char** argv) {
  Args a;
  palpate::cli::parse_or_exit(argc, argv, "palpate-bench-haptic", kUsage, [&](palpate::cli::Arguments& args) {
    const std::string& flag = args.flag();
    if (flag == "--json") a.json = true;
    else if (flag == "--seconds") {
      a.seconds = args.number();
      if (!(a.seconds > 0 && a.seconds <= 86400)) throw std::invalid_argument("--seconds: must be in (0, 86400] s");
    } else if (flag == "--repeat") a.repeat = static_cast<int>(args.integer(1, 100));
    else if (flag == "--scene") a.scene = fs::absolute(args.value()).string();
    else if (flag == "--rate") {
      a.rate = args.number();
      if (!(a.rate > 0 && a.rate <= 10000)) throw std::invalid_argument("--rate: must be in (0, 10000] Hz");
    } else if (flag == "--server-haptic-rate") {
      a.server_haptic_rate = args.number();
      if (!(a.server_haptic_rate >= 0 && a.server_haptic_rate <= 10000))
        throw std::invalid_argument("--server-haptic-rate: must be in [0, 10000] Hz");
    } else if (flag == "--replay-truth") {
      a.replay_truth = true;
    } else if (flag == "--set") {
      const std::string assignment = args.value();
      palpate::cli::scene_override(assignment);
      a.overrides.push_back(assignment);
    } else if (palpate::haptic::parse_device_flag(args, a.haptic)) {
    } else if (flag == "--connect") a.connect = args.value();
    else if (flag == "--server") a.server = args.value();
    else return false;
    return true;
  });
  a.overrides = palpate::haptic::with_free_guide(a.overrides);
  if (a.replay_truth && (a.server_haptic_rate <= 0 || !a.connect.empty()))
    palpate::cli::usage_error("palpate-bench-haptic", "--replay-truth: needs --server-haptic-rate and the scene "
                              "file (not --connect)", kUsage);
  return a;
}

// The median run's figure by nearest rank (one of the runs, never the mean of two).
double median(const std::vector<double>& v) { return palpate::cli::quantile(v, 0.5); }

// --replay-truth: the served forces against the scene stepped at the render rate, in
// process (a headless session of the server's session thread without the local models,
// whose contact stiffness would cost a fine cloud about a quarter second a step). One
// step per render tick from the first served to the last, the device at the served
// target (held through ticks whose frame did not arrive); each served force against the
// truth's renderForce after the step with its target.
void print_replay(const Args& a, const palpate::haptic::Result& run) {
  using palpate::haptic::V3;
  if (run.served.empty()) return;
  palpate::SceneOverrides overrides;
  for (const std::string& o : a.overrides) overrides.push_back(palpate::cli::scene_override(o));
  overrides.emplace_back("integrator.dt", std::to_string(1.0 / a.server_haptic_rate));
  palpate::bench::HeadlessSession truth(palpate::load_scene(a.scene, overrides), false);
  std::vector<std::vector<double>> per_segment(run.segments.size());
  std::vector<double> all;
  double peak = 0;
  size_t next = 0, steps = 0;
  V3 device = run.served.front().target;
  for (int64_t tick = run.served.front().haptic_tick; tick <= run.served.back().haptic_tick; ++tick) {
    while (next < run.served.size() && run.served[next].haptic_tick < tick) ++next;
    const bool served = next < run.served.size() && run.served[next].haptic_tick == tick;
    if (served) device = run.served[next].target;
    const palpate::Vec3 f = truth.step({device[0], device[1], device[2]}).render_force;
    ++steps;
    peak = std::max(peak, f.norm());
    if (!served) continue;
    const V3& g = run.served[next].render_force;
    const double e = (palpate::Vec3(g[0], g[1], g[2]) - f).norm();
    all.push_back(e);
    size_t k = 0;
    while (k + 1 < run.segments.size() && run.served[next].t >= run.segments[k + 1].t0) ++k;
    per_segment[k].push_back(e);
  }
  auto row = [&](const char* name, std::vector<double> v) {
    const auto p = palpate::haptic::percentiles(std::move(v));
    std::printf("  %-12s %6zu   p50 %.3g  p99 %.3g (%.2f %% of peak)  max %.3g N\n", name, p.count, p.p50, p.p99,
                peak > 0 ? 100.0 * p.p99 / peak : 0.0, p.max);
  };
  std::printf("== replay: |served - truth|, the truth stepped at %.0f Hz in process (%zu steps, peak %.4g N, %.1f s)\n",
              a.server_haptic_rate, steps, peak, truth.seconds());
  for (size_t k = 0; k < run.segments.size(); ++k) row(run.segments[k].label.c_str(), per_segment[k]);
  row("all", all);
}

}  // namespace

int main(int argc, char** argv) {
  const Args a = parse_args(argc, argv);
  std::unique_ptr<palpate::cli::ServerProcess> child;
  std::string address = a.connect;
  if (address.empty()) {
    child = std::make_unique<palpate::cli::ServerProcess>(
        palpate::cli::program_path(a.server, "palpate-server", argv[0]),
        std::vector<std::string>{"--scene", a.scene, "--rate", std::to_string(a.rate), "--log-level", "error"},
        palpate::cli::ServerProcess::Options{.wait = std::chrono::seconds(120)});
    child->exit_unless_ready("palpate-bench-haptic");
    address = child->address();
  }
  try {
    capnp::ReaderOptions options;
    options.traversalLimitInWords = 256 * 1024 * 1024;
    capnp::EzRpcClient client(address, 7420, options);
    auto& ws = client.getWaitScope();
    auto server = client.getMain<PalpateServer>();
    palpate::haptic::Config config;
    config.servo_hz = a.haptic.haptic_rate;
    config.seconds = a.seconds;
    config.depth = a.haptic.depth;
    std::vector<palpate::haptic::Result> runs;
    std::string scene_name;
    uint32_t particles = 0;
    double coupling_k = 0, coupling_b = 0;
    for (int run = 0; run < a.repeat; ++run) {
      auto open = server.openSessionRequest();
      auto req = open.initRequest();
      auto o = req.initOverrides(static_cast<unsigned>(a.overrides.size()));
      for (unsigned k = 0; k < a.overrides.size(); ++k) o.set(k, a.overrides[k]);
      req.setHapticRateHz(a.server_haptic_rate);
      palpate::haptic::set_device(req, a.haptic.device_stiffness, a.haptic.device_damping, a.haptic.device_force);
      auto opened = open.send().wait(ws);
      auto info = opened.getInfo();
      scene_name = info.getSceneName().cStr();
      particles = info.getParticleCount();
      coupling_k = info.getCoupling().getStiffness();
      coupling_b = info.getCoupling().getDamping();
      auto session = opened.getSession();
      runs.push_back(palpate::haptic::run_palpation(session, info, ws, config));
      session.closeRequest().send().wait(ws);
      if (a.replay_truth) print_replay(a, runs.back());
      if (!a.json) {
        std::printf("== run %d of %d: scene %s (%u particles), %.0f s, servo %.0f Hz, coupling %.0f N/m %.1f N s/m\n",
                    run + 1, a.repeat, scene_name.c_str(), particles, a.seconds, a.haptic.haptic_rate, coupling_k,
                    coupling_b);
        palpate::haptic::print_report(stdout, runs.back());
      }
    }
    std::vector<double> lateness, misses, skipped, latency;
    for (const auto& r : runs) {
      lateness.push_back(r.server.lateness_p99_us);
      misses.push_back(static_cast<double>(r.server.deadline_misses));
      skipped.push_back(static_cast<double>(r.server.skipped_ticks));
      latency.push_back(r.latency_ms.p99);
    }
    if (a.json) {
      std::string runs_json;
      for (size_t k = 0; k < runs.size(); ++k)
        runs_json += std::string(k ? ", " : "") + "{" + palpate::haptic::json_fields(runs[k]) + "}";
      std::printf("{\"scene\": \"%s\", \"scene_file\": \"%s\", \"particles\": %u, \"seconds\": %.3f, "
                  "\"haptic_rate_hz\": %.1f, \"coupling_stiffness\": %.3f, \"coupling_damping\": %.3f, "
                  "\"repeat\": %d, \"median_lateness_p99_us\": %.1f, \"median_deadline_misses\": %.1f, "
                  "\"median_skipped_ticks\": %.1f, \"median_latency_p99_ms\": %.4f, \"runs\": [%s]}\n",
                  scene_name.c_str(), a.connect.empty() ? a.scene.c_str() : "", particles, a.seconds, a.haptic.haptic_rate,
                  coupling_k, coupling_b, a.repeat, median(lateness), median(misses), median(skipped),
                  median(latency), runs_json.c_str());
    } else if (a.repeat > 1) {
      std::printf("== tail figures over %d runs\n", a.repeat);
      for (size_t k = 0; k < runs.size(); ++k)
        std::printf("run %zu            lateness p99 %.0f us, deadline misses %llu, skipped %llu, latency p99 %.3f ms\n",
                    k + 1, lateness[k], static_cast<unsigned long long>(runs[k].server.deadline_misses),
                    static_cast<unsigned long long>(runs[k].server.skipped_ticks), latency[k]);
      std::printf("median           lateness p99 %.0f us, deadline misses %.0f, skipped %.0f, latency p99 %.3f ms\n",
                  median(lateness), median(misses), median(skipped), median(latency));
    }
  } catch (const kj::Exception& e) {
    std::fprintf(stderr, "palpate-bench-haptic: %s\n", e.getDescription().cStr());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate-bench-haptic: %s\n", e.what());
    return 1;
  }
  return 0;
}
