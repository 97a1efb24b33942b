#pragma once
// The Agones lifecycle of palpate-server (--agones): a client of the Agones SDK sidecar's
// REST interface on localhost (AGONES_SDK_HTTP_PORT, default 9358), on the server's KJ
// event loop (the RPC thread; never a simulation thread). Every call is
// `POST PATH` with the body `{}` and `Content-Type: application/json`, bounded by a
// timeout:
//   - /ready once the server listens, retried with backoff while the sidecar does not
//     answer yet (debug log; one warning when it stays down for kReadyWarnAfter);
//   - then /health every period, but only while the health judgement (the same one as
//     /healthz: every real-time session holds its rate) is ok: when a session cannot hold
//     its rate the pings stop, Agones marks the GameServer Unhealthy and replaces it; they
//     resume when the judgement is ok again;
//   - /shutdown, once, when the server stops (main.cpp: after the sessions were closed).
// docs/protocol.md, "Agones"; docs/deployment.md, "Sessions on Kubernetes with Agones".
#include <functional>
#include <string>

#include <kj/async-io.h>
#include <kj/compat/http.h>
#include <kj/timer.h>

#include "server/web.h"

namespace palpate::server {

struct AgonesOptions {
  std::string host = "localhost";  // where the sidecar listens (it binds localhost only)
  unsigned port = 9358;            // AGONES_SDK_HTTP_PORT, or --agones-port
  double health_period_s = 2.0;    // --agones-health-seconds
  double call_timeout_s = 2.0;     // longest wait for one REST call's answer
};

// The sidecar's REST port: AGONES_SDK_HTTP_PORT when set, else 9358. Throws
// std::invalid_argument naming the variable when it is not a port number in [1, 65535].
unsigned agones_port_from_environment();

class AgonesLifecycle {
 public:
  // `healthy` is asked before each ping (a Probe: ok, and the reason when not).
  AgonesLifecycle(kj::Timer& timer, kj::Network& network, AgonesOptions options, std::function<Probe()> healthy);
  ~AgonesLifecycle();

  // POST /ready until the sidecar takes it, then POST /health every period while
  // `healthy` says ok. Never resolves; dropping the promise stops it (no call is left
  // half-sent that matters: the sidecar ignores an unfinished request).
  kj::Promise<void> run();

  // POST /shutdown once, bounded by call_timeout_s. Never rejects: a failure is logged
  // (the process exits anyway; Agones then sees the container end).
  kj::Promise<void> shutdown();

  static constexpr double kReadyWarnAfter = 10.0;  // s of failed /ready calls before the warning

 private:
  // POST path with "{}"; resolves to the HTTP status, rejects when the sidecar cannot
  // be reached or does not answer within call_timeout_s.
  kj::Promise<unsigned> post(kj::StringPtr path);
  kj::Promise<void> ready(double backoff_s);
  kj::Promise<void> health_loop(kj::TimePoint next);

  kj::Timer& timer_;
  AgonesOptions options_;
  std::function<Probe()> healthy_;
  kj::Own<kj::HttpHeaderTable> table_;
  kj::Own<kj::HttpClient> client_;
  kj::TimePoint ready_started_;
  bool warned_ready_ = false;
  bool pinging_ = true;          // false while the judgement says a session misses its rate
  bool warned_ping_ = false;     // a failed /health was logged (reset by a good one)
};

}  // namespace palpate::server
