// palpate-server: serves palpate sessions over Cap'n Proto RPC (protocol/palpate.capnp).
// Usage: kUsage below (palpate-server --help).
//
// Wiring, in order: options -> the default scene validated and built (a scene that
// cannot be served stops here, status 1, before anything listens) -> event loop ->
// listener -> ServerContext (a bootstrap ServerImpl per connection) -> accept loop -> "listening" line
// -> (--agones) Ready, then health pings -> wait for a signal -> stop the pings -> stop
// every simulation thread -> close the sessions -> (--agones) Shutdown -> drop the
// connections -> drop the event loop.
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

#include <malloc.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <filesystem>
#include <optional>
#include <string>

#include <capnp/message.h>
#include <capnp/rpc-twoparty.h>
#include <kj/async-unix.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "cli/arguments.h"
#include "cli/text_file.h"
#include "core/model.h"
#include "server/agones.h"
#include "server/connection.h"
#include "server/rpc_server.h"
#include "server/web.h"

namespace {

namespace fs = std::filesystem;
using palpate::server::ServerContext;
using palpate::server::ServerOptions;

const char* kUsage = R"(usage: palpate-server [options]
Serves palpate sessions over Cap'n Proto RPC (protocol/palpate.capnp, docs/protocol.md)
until SIGINT or SIGTERM. Each session runs one simulation thread: a fixed-rate real-time
loop, or headless stepping on request. Once it accepts connections it prints one line,
"palpate-server listening on ADDR:PORT", on stdout; logs go to stderr.
  --listen ADDR:PORT   where to listen (default 127.0.0.1:7420; port 0: the system picks
                       one, and the listening line names it)
  --scene FILE         the default scene, opened by clients that name none (default:
                       scenes/hertz_cube.json of the source tree). It is validated, its
                       files read and its model built before the server listens
  --scene-dir DIR      the scenes clients open by name, <name>.json, and the folder their
                       node and mesh files must lie in (default: scenes/ of the source tree)
  --http ADDR:PORT     also listen for HTTP there (off by default; port 0: the system picks
                       one): the same RPC protocol over WebSocket at /rpc, the browser
                       viewer at / (its files from --web-root), /healthz and /readyz
                       (docs/protocol.md, "WebSocket"); then a second line is printed,
                       "palpate-server web on http://ADDR:PORT/"
  --web-root DIR       the viewer's built files (default: viewer/ of the build tree, made
                       from clients/viewer when npm was found at configure time)
  --allow-origin O     a page origin (e.g. http://example.org:8080, or * for any) that may
                       open WebSocket RPC sessions besides the server's own pages
                       (repeatable)
  --rate HZ            real-time loop rate of sessions that ask for none, (0, 10000]
                       (default 1000)
  --spin-us US         the loop sleeps until US before a deadline, then spins, [0, 1e6]
                       (default 200)
  --no-realtime        do not ask for SCHED_FIFO (by default the loops get priority 10
                       and the RPC thread 5 when the system allows it)
  --pin                pin threads: with two cores or more, each real-time loop runs on one of
                       cores 1 ... n-1 in turn and the RPC thread, the contact-stiffness
                       workers and headless sessions on core 0 (off by default: on the shared
                       VMs measured so far it did not lower the misses, server/README.md)
  --no-pin             do not pin threads (the default)
  --no-lock-memory     do not lock the server's memory (by default mlockall keeps every page
                       resident, so no tick waits for a page fault, and freed memory stays in
                       the heap for the next model; refused without the privilege: a warning,
                       and it runs unlocked)
  --sndbuf BYTES       SO_SNDBUF of accepted sockets, bounding how far a slow reader falls
                       behind; 0 keeps the system's (default 262144)
  --max-sessions N     sessions at a time, [1, 1024] (default 16)
  --max-particles N    largest cloud a session may have, [8, 8000000] (default 200000)
  --max-sessions-per-connection N
                       live sessions one connection may have opened, [1, 1024] (default 4)
  --max-subscribers N  subscribers per session, [1, 1024] (default 16)
  --max-message-bytes N
                       the largest message a client may send, [65536, 1073741824] bytes
                       (default 16777216); a larger one ends its connection (over
                       WebSocket at most 1 MiB whatever this says)
  --max-wrong-tokens N refused tokens and unknown session ids one connection may send
                       before its attach() and authenticate() are refused outright,
                       [1, 1000000] (default 10); each refusal is answered after
                       --wrong-token-delay-ms, [0, 10000] (default 250)
  --access-token-file FILE
                       a shared secret (one line, at least 32 characters, e.g.
                       `openssl rand -hex 32`): a connection is served nothing but
                       version() until it calls PalpateServer.authenticate with it
                       (docs/protocol.md, "Security model")
  --tls-cert FILE      serve both listeners over TLS with this PEM certificate (chain)
  --tls-key FILE       and this PEM private key (both or neither). Without them a
                       listener on an address other than loopback is warned about: the
                       tokens and every command would cross the network in clear
  --agones             run as an Agones GameServer: tell the Agones SDK sidecar (REST on
                       localhost, port AGONES_SDK_HTTP_PORT, default 9358) POST /ready once
                       listening (retried until the sidecar answers), POST /health every
                       --agones-health-seconds while every real-time session holds its
                       rate (the /healthz judgement; the pings stop while one does not, so
                       Agones replaces the server), and POST /shutdown on SIGINT/SIGTERM
                       after the sessions were closed (docs/deployment.md, "Sessions on
                       Kubernetes with Agones")
  --agones-port PORT   the sidecar's REST port, [1, 65535] (default: AGONES_SDK_HTTP_PORT,
                       else 9358)
  --agones-health-seconds S
                       period of the health pings, [0.2, 3600] s (default 2); the Fleet's
                       health.periodSeconds should match it
  --log-level LEVEL    trace, debug, info, warn, error or off (default warn)
  --help               print this text and exit
Exit status: 0 after SIGINT or SIGTERM; 1 when the default scene cannot be served (the
message names the file, the field and the reason) or the address cannot be used; 2 for a
wrong argument (or, with --agones, an AGONES_SDK_HTTP_PORT that is not a port; or an
access token, certificate or key file that cannot be used: the message names it).
)";

struct HostPort {
  std::string host;
  unsigned port = 0;
};

HostPort host_port(const std::string& flag, const std::string& v) {
  const auto colon = v.rfind(':');
  if (colon == std::string::npos) throw std::invalid_argument(flag + " expects ADDR:PORT, got '" + v + "'");
  const long long port = palpate::cli::integer(v.substr(colon + 1), flag + ": port");
  if (port < 0 || port > 65535) throw std::invalid_argument(flag + ": port must be in [0, 65535], got '" + v + "'");
  return {v.substr(0, colon), static_cast<unsigned>(port)};
}

struct Args {
  std::string host = "127.0.0.1";
  unsigned port = 7420;
  std::optional<HostPort> http;
#ifdef PALPATE_SANITIZED
  bool lock_memory = false;  // the sanitizers' shadow memory cannot be locked
#else
  bool lock_memory = true;
#endif
  palpate::server::WebOptions web;
  std::string log_level = "warn";
  int sndbuf = 256 * 1024;
  ServerOptions options;
  bool agones = false;
  size_t max_message_bytes = palpate::server::kDefaultMaxMessageBytes;
  std::string access_token_file, tls_cert, tls_key;
  std::optional<unsigned> agones_port;  // --agones-port; else from the environment
  palpate::server::AgonesOptions agones_options;
};

Args parse_args(int argc, char** argv) {
  Args a;
  const fs::path source_dir = PALPATE_SOURCE_DIR;
  a.options.scene_dir = source_dir / "scenes";
  a.options.default_scene = source_dir / "scenes" / "hertz_cube.json";
  a.web.root = PALPATE_VIEWER_DIR;
  palpate::cli::parse_or_exit(argc, argv, "palpate-server", kUsage, [&](palpate::cli::Arguments& args) {
    const std::string& flag = args.flag();
    if (flag == "--listen") {
      const HostPort hp = host_port(flag, args.value());
      a.host = hp.host;
      a.port = hp.port;
    } else if (flag == "--http") {
      a.http = host_port(flag, args.value());
    } else if (flag == "--web-root") {
      a.web.root = args.value();
    } else if (flag == "--allow-origin") {
      a.web.allowed_origins.push_back(args.value());
    } else if (flag == "--scene") {
      a.options.default_scene = args.value();
    } else if (flag == "--scene-dir") {
      a.options.scene_dir = args.value();
    } else if (flag == "--rate") {
      a.options.rate_hz = args.number();
      if (!(a.options.rate_hz > 0 && a.options.rate_hz <= 10000))
        throw std::invalid_argument("--rate: must be in (0, 10000] Hz");
    } else if (flag == "--spin-us") {
      a.options.spin_margin_us = args.number(0, 1e6);
    } else if (flag == "--no-realtime") {
      a.options.try_realtime = false;
    } else if (flag == "--pin") {
      a.options.pin_threads = true;
    } else if (flag == "--no-pin") {
      a.options.pin_threads = false;
    } else if (flag == "--no-lock-memory") {
      a.lock_memory = false;
    } else if (flag == "--sndbuf") {
      a.sndbuf = static_cast<int>(args.integer(0, 1 << 30));
    } else if (flag == "--max-particles") {
      a.options.max_particles = args.integer(8, 8000000);
    } else if (flag == "--max-sessions") {
      a.options.max_sessions = static_cast<int>(args.integer(1, 1024));
    } else if (flag == "--max-sessions-per-connection") {
      a.options.max_sessions_per_connection = static_cast<int>(args.integer(1, 1024));
    } else if (flag == "--max-subscribers") {
      a.options.max_subscribers = static_cast<int>(args.integer(1, 1024));
    } else if (flag == "--max-message-bytes") {
      a.max_message_bytes = static_cast<size_t>(args.integer(1 << 16, 1 << 30));
    } else if (flag == "--max-wrong-tokens") {
      a.options.max_wrong_tokens = static_cast<int>(args.integer(1, 1000000));
    } else if (flag == "--wrong-token-delay-ms") {
      a.options.wrong_token_delay_ms = static_cast<int>(args.integer(0, 10000));
    } else if (flag == "--access-token-file") {
      a.access_token_file = args.value();
    } else if (flag == "--tls-cert") {
      a.tls_cert = args.value();
    } else if (flag == "--tls-key") {
      a.tls_key = args.value();
    } else if (flag == "--agones") {
      a.agones = true;
    } else if (flag == "--agones-port") {
      a.agones_port = static_cast<unsigned>(args.integer(1, 65535));
    } else if (flag == "--agones-health-seconds") {
      a.agones_options.health_period_s = args.number(0.2, 3600);
    } else if (flag == "--log-level") {
      a.log_level = args.value();
      if (a.log_level != "off" && spdlog::level::from_str(a.log_level) == spdlog::level::off)
        throw std::invalid_argument("--log-level: '" + a.log_level +
                                    "' is not one of trace, debug, info, warn, error, off");
    } else {
      return false;
    }
    return true;
  });
  return a;
}

// The default scene, as a session that names no scene would get it, validated and
// built (files read, the stable-dt check passed); false after printing why not.
bool check_default_scene(const ServerOptions& options) {
  try {
    capnp::MallocMessageBuilder message;
    message.initRoot<palpate::wire::OpenRequest>().getScene().setServerDefault();
    const palpate::Scene scene =
        palpate::server::session_scene(message.getRoot<palpate::wire::OpenRequest>().asReader(), options);
    palpate::build_model(scene);
    return true;
  } catch (const kj::Exception& e) {
    std::fprintf(stderr, "palpate-server: --scene: %s\n", e.getDescription().cStr());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate-server: --scene: %s\n", e.what());
  }
  return false;
}

struct LogErrors : kj::TaskSet::ErrorHandler {
  void taskFailed(kj::Exception&& e) override { spdlog::debug("connection ended: {}", e.getDescription().cStr()); }
};

kj::Promise<void> accept_loop(kj::ConnectionReceiver& listener, const palpate::server::AcceptOptions& accept,
                              kj::TaskSet& connections, kj::Timer& timer) {
  return listener.accept()
      .then(
          [&](kj::Own<kj::AsyncIoStream> stream) {
            // The socket's options and (TLS) the handshake run in the connection's task, so
            // that a client slow to shake hands never holds up the next accept.
            auto served = palpate::server::prepare_accepted(kj::mv(stream), accept)
                              .then([&accept](kj::Own<kj::AsyncIoStream> s) {
                                auto connection = kj::heap<palpate::server::RpcConnection>(
                                    kj::mv(s), accept.bootstrap(), accept.max_message_bytes);
                                spdlog::debug("connection accepted");
                                auto done = connection->on_disconnect();
                                return done.attach(kj::mv(connection));
                              });
            connections.add(kj::mv(served));
            return kj::Promise<void>(kj::READY_NOW);
          },
          [&timer](kj::Exception&& e) {  // e.g. out of descriptors: back off, keep serving
            spdlog::warn("accept failed: {}", e.getDescription().cStr());
            return timer.afterDelay(10 * kj::MILLISECONDS);
          })
      .then([&]() { return accept_loop(listener, accept, connections, timer); });
}

// Whether `host` (a --listen or --http address) is a loopback address.
bool is_loopback(const std::string& host) {
  return host == "localhost" || host == "::1" || host == "[::1]" || host.rfind("127.", 0) == 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args args = parse_args(argc, argv);
  spdlog::set_level(spdlog::level::from_str(args.log_level));
  spdlog::set_default_logger(spdlog::stderr_color_mt("palpate-server"));
  spdlog::set_level(spdlog::level::from_str(args.log_level));
  if (args.agones) {
    try {
      args.agones_options.port = args.agones_port ? *args.agones_port : palpate::server::agones_port_from_environment();
    } catch (const std::invalid_argument& e) {
      std::fprintf(stderr, "palpate-server: --agones: %s\n", e.what());
      return 2;
    }
  }
  // The secrets and certificates, before anything is built or listens (exit 2 naming the file).
  std::optional<kj::TlsKeypair> tls_keypair;
  try {
    if (!args.access_token_file.empty())
      args.options.access_token = palpate::server::read_access_token(args.access_token_file);
    if (args.tls_cert.empty() != args.tls_key.empty())
      throw std::invalid_argument("--tls-cert and --tls-key go together: give both or neither");
    if (!args.tls_cert.empty()) {
      const std::string cert = palpate::cli::read_text_file(args.tls_cert, "--tls-cert"),
                        key = palpate::cli::read_text_file(args.tls_key, "--tls-key");
      try {
        tls_keypair.emplace(kj::TlsKeypair{kj::TlsPrivateKey(key.c_str()), kj::TlsCertificate(cert.c_str())});
      } catch (const kj::Exception& e) {
        throw std::invalid_argument("--tls-cert " + args.tls_cert + " / --tls-key " + args.tls_key +
                                    ": not a PEM certificate and private key (" + e.getDescription().cStr() + ")");
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate-server: %s\n", e.what());
    return 2;
  }
  std::signal(SIGPIPE, SIG_IGN);
  // Before any thread exists: the signals are blocked and delivered to the event loop. Also
  // before the first model is built: a library the build calls could start a thread (CHOLMOD's
  // OpenMP did, before core kept it to one), and a thread started with SIGTERM unblocked would
  // take it and kill the process.
  kj::UnixEventPort::captureSignal(SIGINT);
  kj::UnixEventPort::captureSignal(SIGTERM);
  if (!check_default_scene(args.options)) return 1;

  // The RPC thread streams the 1 kHz frames: below the simulation threads'
  // SCHED_FIFO priority (10) but above ordinary load. Silently kept SCHED_OTHER
  // when refused (or with --no-realtime).
  // Memory stays resident (current and future pages: models, states, frames), so a tick
  // never waits for a page fault.
  // MCL_FUTURE only where no lock limit can make a later allocation fail (root, which has
  // CAP_IPC_LOCK, or an unlimited RLIMIT_MEMLOCK); elsewhere the memory stays unlocked.
  if (args.lock_memory) {
    rlimit limit{};
    getrlimit(RLIMIT_MEMLOCK, &limit);
    if (geteuid() != 0 && limit.rlim_cur != RLIM_INFINITY)
      spdlog::info("memory not locked: RLIMIT_MEMLOCK is {} bytes (ulimit -l unlimited to lock it)", limit.rlim_cur);
    else if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
      spdlog::warn("mlockall refused ({}): memory is not locked (--no-lock-memory hides this)", std::strerror(errno));
    // Freed memory stays in the heap: a refocus builds a model of tens of MB on its worker
    // and frees the one it replaces, and glibc would hand those blocks back to the system
    // (munmap above its mmap threshold, a trim of the heap's top) and map and zero them again
    // at the next build. Unmapping a thread's pages interrupts every core the process runs
    // on to flush their TLBs, the loop's included. 32 MiB is the largest mmap threshold
    // glibc accepts on 64 bits (larger blocks are still mapped); the heap is trimmed only
    // past 1 GiB of free top. (Measured in docs/verification/surface_map/method.md.)
    if (mallopt(M_MMAP_THRESHOLD, 32 << 20) != 1 || mallopt(M_TRIM_THRESHOLD, 1 << 30) != 1)
      spdlog::warn("mallopt refused: freed memory may be returned to the system");
  }
  // Core 0 for the RPC thread and what it starts (the loops re-pin themselves to 1 ... n-1).
  if (args.options.pin_threads && std::thread::hardware_concurrency() >= 2) {
    cpu_set_t core0;
    CPU_ZERO(&core0);
    CPU_SET(0, &core0);
    pthread_setaffinity_np(pthread_self(), sizeof core0, &core0);
  }
  if (args.options.try_realtime) {
    sched_param param{};
    param.sched_priority = 5;
    if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &param) != 0) spdlog::debug("RPC thread: SCHED_FIFO refused");
  }

  try {
    auto io = kj::setupAsyncIo();
    auto address = io.provider->getNetwork().parseAddress(args.host, args.port).wait(io.waitScope);
    auto listener = address->listen();
    const unsigned port = listener->getPort();

    ServerContext ctx(io, args.options);
    // TLS (--tls-cert): a handshake not finished within 10 s ends its connection.
    kj::Own<kj::TlsContext> tls;
    if (tls_keypair) {
      kj::TlsContext::Options tls_options;
      tls_options.defaultKeypair = *tls_keypair;
      tls_options.timer = io.provider->getTimer();
      tls_options.acceptTimeout = 10 * kj::SECONDS;
      tls = kj::heap<kj::TlsContext>(kj::mv(tls_options));
    }
    // A listener beyond loopback without TLS or without an access token is warned about.
    auto warn_if_exposed = [&](const char* flag, const std::string& host) {
      if (is_loopback(host)) return;
      if (!tls)
        spdlog::warn("{} {}: listening beyond loopback WITHOUT TLS: control tokens, access tokens and every force "
                     "command cross the network in clear text; give --tls-cert and --tls-key, or put a "
                     "TLS-terminating proxy in front (docs/protocol.md, \"Security model\")",
                     flag, host);
      if (args.options.access_token.empty())
        spdlog::warn("{} {}: no --access-token-file: anyone who reaches the port may open sessions "
                     "(docs/protocol.md, \"Security model\")",
                     flag, host);
    };
    warn_if_exposed("--listen", args.host);
    if (args.http) warn_if_exposed("--http", args.http->host);
    palpate::server::AcceptOptions accept;
    accept.sndbuf = args.sndbuf;
    accept.max_message_bytes = args.max_message_bytes;
    accept.tls = tls.get();
    accept.bootstrap = [&ctx] { return ctx.bootstrap_for_connection(); };
    {
      LogErrors log_errors;
      kj::TaskSet connections(log_errors);
      auto accepting = accept_loop(*listener, accept, connections, io.provider->getTimer())
                           .eagerlyEvaluate([](kj::Exception&& e) {
                             spdlog::error("accept loop ended: {}", e.getDescription().cStr());
                           });
      // The web listener (--http): WebSocket RPC, the viewer, the probes.
      kj::Own<kj::ConnectionReceiver> web_listener;
      kj::Own<palpate::server::WebServer> web;
      kj::Promise<void> web_accepting = kj::READY_NOW;
      unsigned web_port = 0;
      if (args.http) {
        auto web_address = io.provider->getNetwork().parseAddress(args.http->host, args.http->port).wait(io.waitScope);
        web_listener = web_address->listen();
        web_port = web_listener->getPort();
        if (!args.web.root.empty() && !fs::is_regular_file(args.web.root / "index.html"))
          spdlog::warn("--web-root {}: no index.html there (the viewer is not built): only /rpc, /healthz and "
                       "/readyz are served",
                       args.web.root.string());
        palpate::server::WebProbes probes;
        probes.ready = [] { return palpate::server::Probe{true, "ok: the default scene is valid"}; };
        probes.health = [&ctx, window = palpate::server::HealthWindow{}]() mutable { return ctx.health_probe(window); };
        web = kj::heap<palpate::server::WebServer>(io.provider->getTimer(), args.web, std::move(probes), accept);
        web_accepting = web->listen(*web_listener).eagerlyEvaluate([](kj::Exception&& e) {
          spdlog::error("web accept loop ended: {}", e.getDescription().cStr());
        });
      }
      std::printf("palpate-server listening on %s:%u%s\n", args.host.c_str(), port, tls ? " (TLS)" : "");
      if (args.http)
        std::printf("palpate-server web on %s://%s:%u/\n", tls ? "https" : "http", args.http->host.c_str(), web_port);
      std::fflush(stdout);
      spdlog::info("scene dir {}, default scene {}, {} Hz", ctx.options.scene_dir.string(),
                   ctx.options.default_scene.string(), ctx.options.rate_hz);
      // --agones: Ready now that it listens, then the health pings (their own judgement
      // window: /healthz probes do not disturb it).
      kj::Own<palpate::server::AgonesLifecycle> agones;
      kj::Promise<void> agones_running = kj::READY_NOW;
      if (args.agones) {
        agones = kj::heap<palpate::server::AgonesLifecycle>(
            io.provider->getTimer(), io.provider->getNetwork(), args.agones_options,
            [&ctx, window = palpate::server::HealthWindow{}]() mutable { return ctx.health_probe(window); });
        agones_running = agones->run().eagerlyEvaluate([](kj::Exception&& e) {
          spdlog::error("Agones lifecycle ended: {}", e.getDescription().cStr());
        });
      }

      auto sigint = io.unixEventPort.onSignal(SIGINT).then([](siginfo_t) { return SIGINT; });
      auto sigterm = io.unixEventPort.onSignal(SIGTERM).then([](siginfo_t) { return SIGTERM; });
      const int sig = sigint.exclusiveJoin(kj::mv(sigterm)).wait(io.waitScope);
      spdlog::info("signal {}: shutting down {} session(s)", sig, ctx.sessions.size());
      agones_running = nullptr;  // no health ping from here on

      // Simulation threads first, while the loop still exists (docs/protocol.md, "Shutdown"),
      // then every subscriber is told (FrameSink.done), for at most a second.
      ctx.stop_all();
      ctx.close_all("server shutting down")
          .exclusiveJoin(io.provider->getTimer().afterDelay(1 * kj::SECONDS))
          .wait(io.waitScope);
      // Then Agones is told (bounded by the call's timeout, 2 s).
      if (agones) agones->shutdown().wait(io.waitScope);
      accepting = nullptr;
      web_accepting = nullptr;
      web = nullptr;
      web_listener = nullptr;
    }  // connections (and with them every session and subscription) go here
    listener = nullptr;
  } catch (const kj::Exception& e) {
    std::fprintf(stderr, "palpate-server: %s\n", e.getDescription().cStr());
    return 1;
  }
  return 0;
}
