// palpate-bench-server: load benchmark of palpate-server (issue #3). Usage: kUsage
// below (palpate-bench-server --help).
#include <fcntl.h>
#include <limits.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <fstream>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <capnp/ez-rpc.h>
#include <kj/async-io.h>
#include <kj/timer.h>

#include "cli/arguments.h"
#include "cli/child_process.h"
#include "cli/statistics.h"
#include "clients/haptic.h"
#include "protocol/palpate.capnp.h"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using palpate::wire::FrameSink;
using palpate::wire::PalpateServer;
using palpate::wire::Session;

const char* kUsage = R"(usage: palpate-bench-server [options]
Load benchmark of palpate-server. Starts the server (palpate-server next to this
executable, on a loopback port the system picks) unless --connect is given, opens one
real-time session on the scene at --rate and attaches:
 - one full-rate subscriber (every tick; scalars only: contact force, indenter), on the
   connection that sends the commands;
 - --viewers viewers at 60 Hz with all positions, each on its own connection.
Every 50 ms it commands a new force (20 + k % 10 N by default, --force) and measures the
command-to-stream latency: from sending setForce to receiving the first frame whose
commandSeq includes it (the client's clock at both ends). After --seconds it reads the
session's statistics and prints a table, or one JSON object. The benchmark's own
thread asks for SCHED_FIFO 5 (a haptic front-end would run real-time too);
"client_fifo" says if it got it.
--soak S runs the same measurement for S seconds while a churn thread plays the hostile
public: it connects, attaches to the session, subscribes at a random rate (some sinks
never return: stalled readers), sends valid and hostile commands (NaN, Inf, 1e12 N:
each must be refused), writes garbage bytes to the port and vanishes without
unsubscribing, at random, without pause. The output adds the server's resident memory
after a warm-up and at the end (rss_start_mb, rss_end_mb, sampled every 10 s in
rss_samples_mb), the recovered blow-ups (recoveries) and what the churn did.
  --json               print one JSON object instead of the table
  --seconds S          measured window, (0, 86400] (default 30)
  --soak S             soak for S seconds, (0, 86400], with the churn thread (replaces
                       --seconds)
  --scene FILE         the scene, served as the server's default scene (default:
                       scenes/hertz_cube.json of the source tree; ignored with --connect,
                       where the server's default scene is used)
  --rate HZ            the session's loop rate, (0, 10000] (default 1000)
  --viewers N          60 Hz viewers of all positions, [0, 32] (default 4)
  --force F            the commanded forces alternate F * (1 + (k % 10) / 20), (0, 1e6] N
                       (default 20: 20 ... 29 N; the hand-scale scenes want about 0.1)
  --sessions N         real-time sessions at once, [1, 64] (default 1): the first as above,
                       each other one opened on a connection of its own with one 60 Hz
                       viewer of all positions. All are measured over the same window (after
                       every session has started): the output adds each session's rate,
                       the fraction of its deadlines missed in the window (late or skipped
                       ticks) and step time ("sessions"), and the worst session's fraction
  --server-cpu C       pin the server it starts to CPU C, [0, 1023]: its RPC thread and every
                       session's loop then share that one core (the capacity of one core)
  --server-arg ARG     one more argument for the server it starts (repeatable), e.g.
                       --server-arg --spin-us --server-arg 0
  --set KEY=VALUE      a scene override of the sessions it opens (OpenRequest.overrides;
                       repeatable), e.g. --set integrator.threads=2
  --connect ADDR:PORT  use this running server instead of starting one
  --server PATH        the server executable to start (default: palpate-server next to
                       this executable)
  --help               print this text and exit
Exit status: 0 when done; 1 when the server does not start, the connection fails or the
server refuses; 2 for a wrong argument.
)";

struct Args {
  bool json = false;
  double seconds = 30.0;
  std::string scene = PALPATE_SOURCE_DIR "/scenes/hertz_cube.json";
  double rate = 1000.0;
  int viewers = 4;
  double soak = 0.0;  // > 0: soak for this many seconds (churn thread on)
  double force = 20.0;  // N: the commands alternate force * (1 + (k % 10) / 20)
  int sessions = 1;
  int server_cpu = -1;  // -1: not pinned
  std::vector<std::string> server_args;
  std::vector<std::string> overrides;  // --set: scene overrides of every session it opens
  std::string connect;
  std::string server;
};

Args parse_args(int argc, char** argv) {
  Args a;
  auto duration = [](palpate::cli::Arguments& args) {
    const double s = args.number();
    if (!(s > 0 && s <= 86400)) throw std::invalid_argument(args.flag() + ": must be in (0, 86400] s");
    return s;
  };
  palpate::cli::parse_or_exit(argc, argv, "palpate-bench-server", kUsage, [&](palpate::cli::Arguments& args) {
    const std::string& flag = args.flag();
    if (flag == "--json") a.json = true;
    else if (flag == "--seconds") a.seconds = duration(args);
    else if (flag == "--soak") a.soak = a.seconds = duration(args);
    else if (flag == "--scene") a.scene = fs::absolute(args.value()).string();
    else if (flag == "--rate") {
      a.rate = args.number();
      if (!(a.rate > 0 && a.rate <= 10000)) throw std::invalid_argument("--rate: must be in (0, 10000] Hz");
    } else if (flag == "--viewers") a.viewers = static_cast<int>(args.integer(0, 32));
    else if (flag == "--force") a.force = args.number(1e-6, 1e6);
    else if (flag == "--sessions") a.sessions = static_cast<int>(args.integer(1, 64));
    else if (flag == "--server-cpu") a.server_cpu = static_cast<int>(args.integer(0, 1023));
    else if (flag == "--server-arg") a.server_args.push_back(args.value());
    else if (flag == "--set") a.overrides.push_back(args.value());
    else if (flag == "--connect") a.connect = args.value();
    else if (flag == "--server") a.server = args.value();
    else return false;
    return true;
  });
  return a;
}

class Recorder final : public FrameSink::Server {
 public:
  uint64_t frames = 0;
  uint64_t last_seq = 0;
  std::map<uint64_t, Clock::time_point> first_seen;  // command seq -> first frame carrying it

 protected:
  kj::Promise<void> frame(FrameContext context) override {
    const auto now = Clock::now();
    ++frames;
    const uint64_t seq = context.getParams().getFrame().getCommandSeq();
    if (seq > last_seq) {
      for (uint64_t s = last_seq + 1; s <= seq; ++s) first_seen.emplace(s, now);
      last_seq = seq;
    }
    return kj::READY_NOW;
  }
  kj::Promise<void> done(DoneContext) override { return kj::READY_NOW; }
};

// Resident memory of a process, MB (VmRSS); NaN if unknown.
// CPU time the hypervisor gave other guests while this one wanted it ("steal", the
// eighth field of /proc/stat's cpu line), all cores, in seconds since boot; NaN if unknown.
double host_steal_seconds() {
  std::ifstream f("/proc/stat");
  std::string cpu;
  unsigned long long user, nice, system, idle, iowait, irq, softirq, steal;
  if (!(f >> cpu >> user >> nice >> system >> idle >> iowait >> irq >> softirq >> steal) || cpu != "cpu") return NAN;
  return static_cast<double>(steal) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

double rss_mb(pid_t pid) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  std::string key;
  while (status >> key) {
    if (key == "VmRSS:") {
      double kb = 0;
      status >> kb;
      return kb / 1024.0;
    }
    status.ignore(1 << 20, '\n');
  }
  return NAN;
}

// A sink that never finishes a frame: a reader that stopped reading.
class StalledSink final : public FrameSink::Server {
 protected:
  kj::Promise<void> frame(FrameContext) override { return kj::NEVER_DONE; }
  kj::Promise<void> done(DoneContext) override { return kj::READY_NOW; }
};

class CountingSink final : public FrameSink::Server {
 protected:
  kj::Promise<void> frame(FrameContext) override { return kj::READY_NOW; }
  kj::Promise<void> done(DoneContext) override { return kj::READY_NOW; }
};

struct Churn {
  std::atomic<uint64_t> connections{0}, subscriptions{0}, stalled{0}, valid_commands{0}, hostile_commands{0},
      hostile_accepted{0}, garbage{0}, errors{0};
};

// Random raw bytes to the server's port, then hang up.
void send_garbage(const std::string& address, std::mt19937_64& rng) {
  const auto colon = address.rfind(':');
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(std::atoi(address.c_str() + colon + 1)));
  if (inet_pton(AF_INET, address.substr(0, colon).c_str(), &addr.sin_addr) != 1) return;
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return;
  if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) {
    std::vector<uint8_t> junk(1 + rng() % 65536);
    for (auto& b : junk) b = static_cast<uint8_t>(rng());
    if (rng() % 2) std::fill(junk.begin(), junk.begin() + std::min<size_t>(8, junk.size()), 0xff);
    [[maybe_unused]] const ssize_t n = write(fd, junk.data(), junk.size());
  }
  close(fd);
}

// The churn thread: clients that come, misbehave and vanish, until `stop`.
void churn(const std::string& address, uint32_t session_id, const std::atomic<bool>& stop, Churn& c) {
  std::mt19937_64 rng(20261201);
  capnp::ReaderOptions options;
  options.traversalLimitInWords = 256 * 1024 * 1024;
  const double hostile[] = {NAN, HUGE_VAL, -HUGE_VAL, 1e12, -1e12};
  while (!stop.load()) {
    if (rng() % 5 == 0) {
      send_garbage(address, rng);
      ++c.garbage;
      continue;
    }
    try {
      capnp::EzRpcClient client(address, 7420, options);
      auto& ws = client.getWaitScope();
      auto& timer = client.getIoProvider().getTimer();
      ++c.connections;
      auto attach = client.getMain<PalpateServer>().attachRequest();
      attach.setSessionId(session_id);
      auto session = attach.send().wait(ws).getSession();
      std::vector<palpate::wire::Subscription::Client> subs;
      for (int k = static_cast<int>(rng() % 3); k > 0; --k) {
        auto req = session.subscribeRequest();
        const bool stall = rng() % 3 == 0;
        if (stall) {
          req.setSink(kj::heap<StalledSink>());
          ++c.stalled;
        } else {
          req.setSink(kj::heap<CountingSink>());
        }
        const double rates[] = {0.0, 60.0, 250.0, 1000.0};
        req.getOptions().setRateHz(rates[rng() % 4]);
        req.getOptions().getFields().setPositions(rng() % 2);
        req.getOptions().getFields().setContacts(rng() % 2);
        subs.push_back(req.send().wait(ws).getSubscription());
        ++c.subscriptions;
      }
      for (int k = static_cast<int>(rng() % 6); k > 0; --k) {
        auto req = session.setForceRequest();
        const bool bad = rng() % 2;
        req.setNewtons(bad ? hostile[rng() % 5] : 10.0 + static_cast<double>(rng() % 3200) / 10.0);
        try {
          req.send().wait(ws);
          ++(bad ? c.hostile_accepted : c.valid_commands);
        } catch (const kj::Exception&) {
          ++(bad ? c.hostile_commands : c.errors);
        }
      }
      timer.afterDelay((20 + rng() % 500) * kj::MILLISECONDS).wait(ws);
      // Vanish: the connection drops with its subscriptions still open.
    } catch (const kj::Exception&) {
      ++c.errors;
    }
  }
}

// Nearest-rank quantiles: cli/statistics.h, one definition for the project.
using palpate::cli::quantile;

}  // namespace

int main(int argc, char** argv) {
  const Args a = parse_args(argc, argv);
  std::unique_ptr<palpate::cli::ServerProcess> child;
  std::string address = a.connect;
  if (address.empty()) {
    std::vector<std::string> server_args{"--scene", a.scene, "--rate", std::to_string(a.rate), "--max-sessions",
                                         std::to_string(std::max(16, a.sessions))};
    server_args.insert(server_args.end(), a.server_args.begin(), a.server_args.end());
    child = std::make_unique<palpate::cli::ServerProcess>(
        palpate::cli::program_path(a.server, "palpate-server", argv[0]), server_args,
        palpate::cli::ServerProcess::Options{.wait = std::chrono::seconds(120), .cpu = a.server_cpu});
    child->exit_unless_ready("palpate-bench-server");
    address = child->address();
  }

  // The client plays a haptic front-end: SCHED_FIFO 5 like the server's RPC
  // thread when allowed (after the server child was forked), else ordinary.
  sched_param param{};
  param.sched_priority = 5;
  const bool client_fifo = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param) == 0;

  try {
    capnp::ReaderOptions options;
    options.traversalLimitInWords = 256 * 1024 * 1024;
    capnp::EzRpcClient control(address, 7420, options);
    auto& ws = control.getWaitScope();
    auto& timer = control.getIoProvider().getTimer();
    auto server = control.getMain<PalpateServer>();
    auto set_overrides = [&a](auto request) {
      auto list = request.initOverrides(static_cast<unsigned>(a.overrides.size()));
      for (size_t k = 0; k < a.overrides.size(); ++k) list.set(static_cast<unsigned>(k), a.overrides[k]);
    };
    auto open = server.openSessionRequest();
    open.initRequest().setRateHz(a.rate);
    set_overrides(open.getRequest());
    auto opened = open.send().wait(ws);
    auto session = opened.getSession();
    const uint32_t particles = opened.getInfo().getParticleCount();
    const uint32_t session_id = opened.getInfo().getSessionId();

    // The full-rate subscriber, on the control connection.
    auto recorder_owner = kj::heap<Recorder>();
    Recorder& recorder = *recorder_owner;
    auto sub = session.subscribeRequest();
    sub.setSink(kj::mv(recorder_owner));
    sub.getOptions().setRateHz(0);
    auto full_rate = sub.send().wait(ws).getSubscription();

    // Viewers: their own connections (same event loop, this thread).
    std::vector<std::unique_ptr<capnp::EzRpcClient>> viewer_connections;
    std::vector<Recorder*> viewers;
    std::vector<PalpateServer::Client> viewer_servers;
    std::vector<Session::Client> viewer_sessions;
    std::vector<palpate::wire::Subscription::Client> viewer_subs;
    for (int v = 0; v < a.viewers; ++v) {
      viewer_connections.push_back(std::make_unique<capnp::EzRpcClient>(address, 7420, options));
      viewer_servers.push_back(viewer_connections.back()->getMain<PalpateServer>());
      auto att = viewer_servers.back().attachRequest();
      att.setSessionId(session_id);
      viewer_sessions.push_back(att.send().wait(ws).getSession());
      auto owner = kj::heap<Recorder>();
      viewers.push_back(owner.get());
      auto req = viewer_sessions.back().subscribeRequest();
      req.setSink(kj::mv(owner));
      req.getOptions().setRateHz(60);
      req.getOptions().getFields().setPositions(true);
      viewer_subs.push_back(req.send().wait(ws).getSubscription());
    }

    // --sessions: the others, each on a connection of its own with one 60 Hz viewer.
    std::vector<std::unique_ptr<capnp::EzRpcClient>> other_connections;
    std::vector<PalpateServer::Client> other_servers;
    std::vector<palpate::wire::Subscription::Client> other_subs;
    std::vector<Session::Client> sessions;
    sessions.push_back(Session::Client(session));
    for (int k = 1; k < a.sessions; ++k) {
      other_connections.push_back(std::make_unique<capnp::EzRpcClient>(address, 7420, options));
      other_servers.push_back(other_connections.back()->getMain<PalpateServer>());
      auto req = other_servers.back().openSessionRequest();
      req.initRequest().setRateHz(a.rate);
      set_overrides(req.getRequest());
      sessions.push_back(req.send().wait(ws).getSession());
      auto view = sessions.back().subscribeRequest();
      view.setSink(kj::heap<Recorder>());
      view.getOptions().setRateHz(60);
      view.getOptions().getFields().setPositions(true);
      other_subs.push_back(view.send().wait(ws).getSubscription());
    }

    // Warm-up, then the measured window: a command every 50 ms.
    timer.afterDelay((a.soak > 0 ? 5000 : a.sessions > 1 ? 1000 : 500) * kj::MILLISECONDS).wait(ws);
    const pid_t server_pid = child ? child->pid() : -1;
    const double rss_start = server_pid > 0 ? rss_mb(server_pid) : NAN;
    std::vector<double> rss_samples;
    Churn churned;
    std::atomic<bool> stop_churn{false};
    std::thread churn_thread;
    if (a.soak > 0) churn_thread = std::thread([&] { churn(address, session_id, stop_churn, churned); });
    auto last_sample = Clock::now();
    auto last_progress = Clock::now();
    struct WindowCounts {
      int64_t ticks = 0;
      double elapsed_s = 0.0;
      uint64_t misses = 0, skipped = 0;
    };
    auto window_counts = [&](Session::Client& s) {
      auto response = s.statsRequest().send().wait(ws);
      const auto st = response.getStats();
      return WindowCounts{st.getTicks(), st.getElapsedSeconds(), st.getDeadlineMisses(), st.getSkippedTicks()};
    };
    std::vector<WindowCounts> window_start;
    for (auto& s : sessions) window_start.push_back(window_counts(s));
    const int64_t ticks0 = window_start[0].ticks;
    const double elapsed0 = window_start[0].elapsed_s;
    const double steal0 = host_steal_seconds();
    std::map<uint64_t, Clock::time_point> sent;
    const auto start = Clock::now();
    for (int k = 0; std::chrono::duration<double>(Clock::now() - start).count() < a.seconds; ++k) {
      auto req = session.setForceRequest();
      req.setNewtons(a.force * (1.0 + (k % 10) / 20.0));
      const auto t = Clock::now();
      const uint64_t seq = req.send().wait(ws).getSeq();
      sent.emplace(seq, t);
      timer.afterDelay(50 * kj::MILLISECONDS).wait(ws);
      if (a.soak > 0 && Clock::now() - last_sample >= std::chrono::seconds(10)) {
        last_sample = Clock::now();
        if (server_pid > 0) rss_samples.push_back(rss_mb(server_pid));
      }
      if (a.soak > 0 && Clock::now() - last_progress >= std::chrono::seconds(60)) {
        last_progress = Clock::now();
        std::fprintf(stderr, "palpate-bench-server: soak %.0f / %.0f s, server RSS %.1f MB, %llu churn connections\n",
                     std::chrono::duration<double>(Clock::now() - start).count(), a.seconds,
                     server_pid > 0 ? rss_mb(server_pid) : NAN,
                     static_cast<unsigned long long>(churned.connections.load()));
      }
    }
    stop_churn = true;
    if (churn_thread.joinable()) churn_thread.join();
    timer.afterDelay(1000 * kj::MILLISECONDS).wait(ws);  // let the server drop the vanished clients
    const double rss_end = server_pid > 0 ? rss_mb(server_pid) : NAN;
    auto stats_response = session.statsRequest().send().wait(ws);
    auto stats = stats_response.getStats();
    // Every session over the same window: rate, deadline-miss ratio, step time.
    std::string sessions_json = "[", sessions_table;
    double worst_miss_ratio = 0.0;
    for (size_t k = 0; k < sessions.size(); ++k) {
      auto response = sessions[k].statsRequest().send().wait(ws);
      const auto st = response.getStats();
      const WindowCounts& w0 = window_start[k];
      const double ticks = static_cast<double>(st.getTicks() - w0.ticks);
      const double seconds = st.getElapsedSeconds() - w0.elapsed_s;
      const double session_rate = seconds > 0 ? ticks / seconds : 0.0;
      // The deadlines of the window that were missed: ticks that ended late, and those
      // skipped when the loop fell more than a period behind.
      const double skipped = static_cast<double>(st.getSkippedTicks() - w0.skipped);
      const double deadlines = ticks + skipped;
      const double ratio =
          deadlines > 0 ? (static_cast<double>(st.getDeadlineMisses() - w0.misses) + skipped) / deadlines : 1.0;
      worst_miss_ratio = std::max(worst_miss_ratio, ratio);
      char line[256];
      std::snprintf(line, sizeof line,
                    "%s{\"rate_hz\": %.2f, \"window_missed_deadlines\": %.6f, \"step_p50_us\": %.1f, \"step_p99_us\": %.1f}",
                    k ? ", " : "", session_rate, ratio, st.getStepUs().getP50(), st.getStepUs().getP99());
      sessions_json += line;
      std::snprintf(line, sizeof line, "session %-2zu        %.1f Hz, deadlines missed %.3f %% in the window (late or skipped), step p50 %.0f us, p99 %.0f us\n",
                    k + 1, session_rate, 100.0 * ratio, st.getStepUs().getP50(), st.getStepUs().getP99());
      sessions_table += line;
    }
    sessions_json += "]";

    std::vector<double> latency_ms;
    for (const auto& [seq, t] : sent)
      if (auto it = recorder.first_seen.find(seq); it != recorder.first_seen.end())
        latency_ms.push_back(std::chrono::duration<double, std::milli>(it->second - t).count());
    const double window_s = stats.getElapsedSeconds() - elapsed0;
    const double rate = window_s > 0 ? (stats.getTicks() - ticks0) / window_s : 0.0;
    const double misses = static_cast<double>(stats.getDeadlineMisses());
    const double host_steal = host_steal_seconds() - steal0;
    const double miss_ratio = stats.getTicks() > 0 ? misses / static_cast<double>(stats.getTicks()) : 0.0;

    std::vector<uint64_t> dropped, received;
    uint64_t full_rate_dropped = 0;
    for (auto s : stats.getSubscribers()) {
      if (s.getRateHz() == 0) full_rate_dropped = s.getDropped();
      else dropped.push_back(s.getDropped());
    }
    for (Recorder* v : viewers) received.push_back(v->frames);
    auto list = [](const std::vector<uint64_t>& v) {
      std::string s = "[";
      for (size_t k = 0; k < v.size(); ++k) s += (k ? ", " : "") + std::to_string(v[k]);
      return s + "]";
    };
    const auto step = stats.getStepUs();
    const auto late = stats.getLatenessUs();
    auto number = [](double x) { return std::isfinite(x) ? std::to_string(x) : std::string("null"); };
    std::string soak_json;
    if (a.soak > 0) {
      std::string samples = "[";
      for (size_t k = 0; k < rss_samples.size(); ++k) samples += (k ? ", " : "") + number(rss_samples[k]);
      samples += "]";
      auto count = [](const std::atomic<uint64_t>& v) { return std::to_string(v.load()); };
      soak_json = ", \"soak_seconds\": " + number(a.soak) + ", \"rss_start_mb\": " + number(rss_start) +
                  ", \"rss_end_mb\": " + number(rss_end) + ", \"rss_samples_mb\": " + samples +
                  ", \"recoveries\": " + std::to_string(stats.getBlowUps()) +
                  ", \"churn\": {\"connections\": " + count(churned.connections) +
                  ", \"subscriptions\": " + count(churned.subscriptions) + ", \"stalled_sinks\": " +
                  count(churned.stalled) + ", \"valid_commands\": " + count(churned.valid_commands) +
                  ", \"hostile_commands_refused\": " + count(churned.hostile_commands) +
                  ", \"hostile_commands_accepted\": " + count(churned.hostile_accepted) +
                  ", \"garbage_connections\": " + count(churned.garbage) + ", \"errors\": " +
                  count(churned.errors) + "}";
    }
    if (a.json) {
      std::printf(
          "{\"scene\": \"%s\", \"particles\": %u, \"seconds\": %.1f, \"target_rate_hz\": %.1f, \"rate_hz\": %.2f, "
          "\"ticks\": %lld, \"step_p50_us\": %.1f, \"step_p99_us\": %.1f, \"step_max_us\": %.1f, "
          "\"lateness_p50_us\": %.1f, \"lateness_p99_us\": %.1f, \"lateness_max_us\": %.1f, "
          "\"deadline_misses\": %llu, \"deadline_miss_ratio\": %.6f, \"misses_late_start\": %llu, "
          "\"misses_long_step\": %llu, \"host_steal_s\": %s, \"pinned\": %s, \"skipped_ticks\": %llu, "
          "\"latency_p50_ms\": %.3f, \"latency_p99_ms\": %.3f, \"latency_max_ms\": %.3f, \"commands\": %zu, "
          "\"full_rate_frames\": %llu, \"full_rate_dropped\": %llu, \"dropped_frames\": %s, "
          "\"viewer_frames\": %s, \"blow_ups\": %u, \"realtime_priority\": %s, \"client_fifo\": %s, "
          "\"server_cpu\": %d, \"sessions\": %s, \"worst_window_missed_deadlines\": %.6f%s}\n",
          a.scene.c_str(), particles, a.seconds, stats.getTargetRateHz(), rate,
          static_cast<long long>(stats.getTicks()), step.getP50(), step.getP99(), step.getMax(), late.getP50(),
          late.getP99(), late.getMax(), static_cast<unsigned long long>(stats.getDeadlineMisses()), miss_ratio,
          static_cast<unsigned long long>(stats.getMissesLateStart()),
          static_cast<unsigned long long>(stats.getMissesLongStep()), number(host_steal).c_str(),
          stats.getPinned() ? "true" : "false", static_cast<unsigned long long>(stats.getSkippedTicks()), quantile(latency_ms, 0.5),
          quantile(latency_ms, 0.99), quantile(latency_ms, 1.0), latency_ms.size(),
          static_cast<unsigned long long>(recorder.frames), static_cast<unsigned long long>(full_rate_dropped),
          list(dropped).c_str(), list(received).c_str(), stats.getBlowUps(),
          stats.getRealtimePriority() ? "true" : "false", client_fifo ? "true" : "false", a.server_cpu,
          sessions_json.c_str(), worst_miss_ratio, soak_json.c_str());
    } else {
      std::printf("scene %s (%u particles), %.0f s at %.0f Hz target, 1 full-rate subscriber + %d viewers at 60 Hz\n",
                  a.scene.c_str(), particles, a.seconds, stats.getTargetRateHz(), a.viewers);
      std::printf("achieved rate     %.1f Hz (%lld ticks)%s\n", rate, static_cast<long long>(stats.getTicks()),
                  stats.getRealtimePriority() ? ", SCHED_FIFO" : "");
      std::printf("step time         p50 %.0f us, p99 %.0f us, max %.0f us\n", step.getP50(), step.getP99(),
                  step.getMax());
      std::printf("tick lateness     p50 %.0f us, p99 %.0f us, max %.0f us\n", late.getP50(), late.getP99(),
                  late.getMax());
      std::printf("deadline misses   %llu (%.3f %%): %llu started late, %llu steps overran; %llu ticks skipped%s\n",
                  static_cast<unsigned long long>(stats.getDeadlineMisses()), 100.0 * miss_ratio,
                  static_cast<unsigned long long>(stats.getMissesLateStart()),
                  static_cast<unsigned long long>(stats.getMissesLongStep()),
                  static_cast<unsigned long long>(stats.getSkippedTicks()), stats.getPinned() ? ", loop pinned" : "");
      std::printf("host steal        %.3f s of CPU taken by the hypervisor during the run (all cores)\n", host_steal);
      std::printf("command->stream   p50 %.2f ms, p99 %.2f ms, max %.2f ms (%zu commands)\n",
                  quantile(latency_ms, 0.5), quantile(latency_ms, 0.99), quantile(latency_ms, 1.0),
                  latency_ms.size());
      std::printf("full-rate frames  %llu received, %llu dropped\n", static_cast<unsigned long long>(recorder.frames),
                  static_cast<unsigned long long>(full_rate_dropped));
      std::printf("viewer frames     received %s, dropped %s\n", list(received).c_str(), list(dropped).c_str());
      if (a.sessions > 1) std::printf("%s", sessions_table.c_str());
      if (a.soak > 0) {
        std::printf("server memory     %.1f MB after warm-up, %.1f MB at the end\n", rss_start, rss_end);
        std::printf("recoveries        %u blow-ups recovered\n", stats.getBlowUps());
        std::printf("churn             %llu connections, %llu subscriptions (%llu stalled), %llu valid and %llu "
                    "refused hostile commands (%llu hostile accepted), %llu garbage connections, %llu errors\n",
                    static_cast<unsigned long long>(churned.connections.load()),
                    static_cast<unsigned long long>(churned.subscriptions.load()),
                    static_cast<unsigned long long>(churned.stalled.load()),
                    static_cast<unsigned long long>(churned.valid_commands.load()),
                    static_cast<unsigned long long>(churned.hostile_commands.load()),
                    static_cast<unsigned long long>(churned.hostile_accepted.load()),
                    static_cast<unsigned long long>(churned.garbage.load()),
                    static_cast<unsigned long long>(churned.errors.load()));
      }
    }
  } catch (const kj::Exception& e) {
    std::fprintf(stderr, "palpate-bench-server: %s\n", e.getDescription().cStr());
    return 1;
  }
  return 0;
}
