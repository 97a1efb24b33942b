// palpate-server: serves palpate sessions over Cap'n Proto RPC (protocol/palpate.capnp).
//
//   palpate-server [--listen 127.0.0.1:7420] [--scene FILE] [--scene-dir DIR] [--rate HZ]
//                  [--spin-us US] [--no-realtime] [--sndbuf BYTES] [--max-sessions N] [--max-particles N]
//                  [--log-level trace|debug|info|warn|error|off]
//
// Serves until SIGINT/SIGTERM. Prints one line "palpate-server listening on ADDR:PORT"
// to stdout once it accepts connections (with --listen ...:0 the port is the one
// the system picked). Wiring, in order: options -> event loop -> listener ->
// ServerContext + bootstrap ServerImpl -> accept loop -> wait for a signal ->
// stop every simulation thread -> drop the connections -> drop the event loop.
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

#include <pthread.h>
#include <sched.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include <capnp/rpc-twoparty.h>
#include <kj/async-unix.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "server/session.h"

namespace {

namespace fs = std::filesystem;
using palpate::server::ServerContext;
using palpate::server::ServerImpl;
using palpate::server::ServerOptions;

struct Args {
  std::string host = "127.0.0.1";
  unsigned port = 7420;
  std::string log_level = "warn";
  int sndbuf = 256 * 1024;
  ServerOptions options;
};

[[noreturn]] void usage(const std::string& error) {
  std::fprintf(stderr,
               "palpate-server: %s\n"
               "usage: palpate-server [--listen ADDR:PORT] [--scene FILE] [--scene-dir DIR] [--rate HZ]\n"
               "                      [--spin-us US] [--no-realtime] [--sndbuf BYTES] [--max-sessions N] [--max-particles N]\n"
               "                      [--log-level trace|debug|info|warn|error|off]\n",
               error.c_str());
  std::exit(2);
}

double number(const std::string& flag, const std::string& text) {
  try {
    size_t used = 0;
    const double v = std::stod(text, &used);
    if (used != text.size()) throw std::invalid_argument(text);
    return v;
  } catch (const std::exception&) {
    usage(flag + " expects a number, got '" + text + "'");
  }
}

Args parse_args(int argc, char** argv) {
  Args a;
  const fs::path source_dir = PALPATE_SOURCE_DIR;
  a.options.scene_dir = source_dir / "scenes";
  a.options.default_scene = source_dir / "scenes" / "hertz_cube.json";
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage(flag + " needs a value");
      return argv[++i];
    };
    if (flag == "--listen") {
      const std::string v = value();
      const auto colon = v.rfind(':');
      if (colon == std::string::npos) usage("--listen expects ADDR:PORT, got '" + v + "'");
      a.host = v.substr(0, colon);
      const double port = number(flag, v.substr(colon + 1));
      if (port < 0 || port > 65535 || port != static_cast<unsigned>(port)) usage("--listen: bad port in '" + v + "'");
      a.port = static_cast<unsigned>(port);
    } else if (flag == "--scene") {
      a.options.default_scene = value();
    } else if (flag == "--scene-dir") {
      a.options.scene_dir = value();
    } else if (flag == "--rate") {
      a.options.rate_hz = number(flag, value());
      if (!(a.options.rate_hz > 0 && a.options.rate_hz <= 10000)) usage("--rate must be in (0, 10000] Hz");
    } else if (flag == "--spin-us") {
      a.options.spin_margin_us = number(flag, value());
      if (!(a.options.spin_margin_us >= 0 && a.options.spin_margin_us <= 1e6)) usage("--spin-us must be in [0, 1e6]");
    } else if (flag == "--no-realtime") {
      a.options.try_realtime = false;
    } else if (flag == "--sndbuf") {
      a.sndbuf = static_cast<int>(number(flag, value()));
    } else if (flag == "--max-particles") {
      a.options.max_particles = number(flag, value());
    } else if (flag == "--max-sessions") {
      a.options.max_sessions = static_cast<int>(number(flag, value()));
    } else if (flag == "--log-level") {
      a.log_level = value();
    } else if (flag == "--help" || flag == "-h") {
      usage("help");
    } else {
      usage("unknown option " + flag);
    }
  }
  return a;
}

// One client connection: its stream, the two-party network and the RPC system.
struct Connection {
  Connection(kj::Own<kj::AsyncIoStream> s, capnp::Capability::Client bootstrap)
      : stream(kj::mv(s)),
        network(*stream, capnp::rpc::twoparty::Side::SERVER, reader_options()),
        rpc(capnp::makeRpcServer(network, kj::mv(bootstrap))) {
    rpc.setFlowLimit(1 << 20);  // words of incoming calls in flight per connection
  }
  static capnp::ReaderOptions reader_options() {
    capnp::ReaderOptions o;
    o.traversalLimitInWords = 64 * 1024 * 1024;  // 512 MiB: inline scenes with node lists
    return o;
  }
  kj::Own<kj::AsyncIoStream> stream;
  capnp::TwoPartyVatNetwork network;
  capnp::RpcSystem<capnp::rpc::twoparty::VatId> rpc;
};

struct LogErrors : kj::TaskSet::ErrorHandler {
  void taskFailed(kj::Exception&& e) override { spdlog::debug("connection ended: {}", e.getDescription().cStr()); }
};

kj::Promise<void> accept_loop(kj::ConnectionReceiver& listener, capnp::Capability::Client bootstrap,
                              kj::TaskSet& connections, int sndbuf, kj::Timer& timer) {
  return listener.accept()
      .then(
          [&, bootstrap, sndbuf](kj::Own<kj::AsyncIoStream> stream) mutable {
            // A small send buffer bounds how far a slow reader can fall behind (capnp.md §2).
            if (sndbuf > 0) stream->setsockopt(SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof sndbuf);
            const int one = 1;
            stream->setsockopt(IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
            stream->setsockopt(SOL_SOCKET, SO_KEEPALIVE, &one, sizeof one);
            auto connection = kj::heap<Connection>(kj::mv(stream), bootstrap);
            spdlog::debug("connection accepted");
            auto done = connection->network.onDisconnect();
            connections.add(done.attach(kj::mv(connection)));
            return kj::Promise<void>(kj::READY_NOW);
          },
          [&timer](kj::Exception&& e) {  // e.g. out of descriptors: back off, keep serving
            spdlog::warn("accept failed: {}", e.getDescription().cStr());
            return timer.afterDelay(10 * kj::MILLISECONDS);
          })
      .then([&, bootstrap, sndbuf]() mutable { return accept_loop(listener, bootstrap, connections, sndbuf, timer); });
}

}  // namespace

int main(int argc, char** argv) {
  Args args = parse_args(argc, argv);
  spdlog::set_level(spdlog::level::from_str(args.log_level));
  spdlog::set_default_logger(spdlog::stderr_color_mt("palpate-server"));
  spdlog::set_level(spdlog::level::from_str(args.log_level));
  std::signal(SIGPIPE, SIG_IGN);
  // Before any thread exists: the signals are blocked and delivered to the event loop.
  kj::UnixEventPort::captureSignal(SIGINT);
  kj::UnixEventPort::captureSignal(SIGTERM);

  // The RPC thread streams the 1 kHz frames: below the simulation threads'
  // SCHED_FIFO priority (10) but above ordinary load. Silently kept SCHED_OTHER
  // when refused (or with --no-realtime).
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
    {
      LogErrors log_errors;
      kj::TaskSet connections(log_errors);
      capnp::Capability::Client bootstrap = kj::heap<ServerImpl>(ctx);
      auto accepting = accept_loop(*listener, bootstrap, connections, args.sndbuf, io.provider->getTimer())
                           .eagerlyEvaluate([](kj::Exception&& e) {
                             spdlog::error("accept loop ended: {}", e.getDescription().cStr());
                           });
      std::printf("palpate-server listening on %s:%u\n", args.host.c_str(), port);
      std::fflush(stdout);
      spdlog::info("scene dir {}, default scene {}, {} Hz", ctx.options.scene_dir.string(),
                   ctx.options.default_scene.string(), ctx.options.rate_hz);

      auto sigint = io.unixEventPort.onSignal(SIGINT).then([](siginfo_t) { return SIGINT; });
      auto sigterm = io.unixEventPort.onSignal(SIGTERM).then([](siginfo_t) { return SIGTERM; });
      const int sig = sigint.exclusiveJoin(kj::mv(sigterm)).wait(io.waitScope);
      spdlog::info("signal {}: shutting down {} session(s)", sig, ctx.sessions.size());

      // Simulation threads first, while the loop still exists (capnp.md pitfall).
      ctx.stop_all();
      accepting = nullptr;
    }  // connections (and with them every session and subscription) go here
    listener = nullptr;
  } catch (const kj::Exception& e) {
    std::fprintf(stderr, "palpate-server: %s\n", e.getDescription().cStr());
    return 1;
  }
  return 0;
}
