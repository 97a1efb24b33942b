#pragma once
// The RPC side of the server (runs on the KJ event-loop thread only): ServerContext (what
// every connection shares) and ServerImpl (the bootstrap capability); the sessions are
// server/session.h (SessionImpl, one Simulation each). Nothing here is touched by a
// simulation thread; they meet in Simulation (sim_loop.h), whose members say which side
// owns them.
#include <cstdint>
#include <filesystem>
#include <list>
#include <map>
#include <memory>
#include <set>
#include <string>

#include <kj/async-io.h>

#include "protocol/palpate.capnp.h"
#include "server/access.h"
#include "server/requests.h"
#include "server/sim_loop.h"
#include "server/web.h"

namespace palpate::server {

class SessionImpl;

// What one asker of ServerContext::health_probe saw at its previous probe. Each asker
// (the /healthz endpoint, the Agones pinger) keeps its own, so that one's probes never
// shorten or reset the interval another one judges. RPC thread only.
class HealthWindow {
 private:
  friend struct ServerContext;
  struct Sample {
    int64_t ticks = 0;
    double elapsed_s = 0.0;
    uint64_t deadline_misses = 0;
    std::string failure;  // the verdict on the interval that ended here: empty when it held
  };
  std::map<uint32_t, Sample> samples_;  // by session id, at this asker's previous probe
};

// Shared by every connection: options, the live sessions (for shutdown) and a
// TaskSet for fire-and-forget calls. RPC thread only.
struct ServerContext {
  ServerContext(kj::AsyncIoContext& io, ServerOptions options);
  kj::AsyncIoContext& io;
  ServerOptions options;
  std::map<uint32_t, SessionImpl*> sessions;  // by id (random, server/access.h), starting ones included
  // Stamped by a timer of this thread every RpcHeartbeat::kPeriodNs; the real-time loops
  // give way when it is stale (server/deadlines.h).
  RpcHeartbeat heartbeat;
  uint32_t next_subscriber_id = 1;

  // A new connection's bootstrap capability, with its own ConnectionState (its limits):
  // the full PalpateServer, or, with an access token (--access-token-file), one that
  // serves only version() and authenticate() until the token is presented.
  capnp::Capability::Client bootstrap_for_connection();
  // A session id no live session has (random_session_id()).
  uint32_t new_session_id() const;
  // A refused token or unknown session id on `connection`: counted, and the call fails
  // with `message` after options.wrong_token_delay_ms (the delay does not hold the loop).
  kj::Promise<void> refuse_guess(ConnectionState& connection, std::string message);
  // Refuses the call at once when `connection` has been refused max_wrong_tokens times.
  void check_guesses_left(const ConnectionState& connection, const char* method) const;

  // Stops every simulation thread (before the event loop goes away). Waits for
  // starts in progress to reach the end of their stage.
  void stop_all();
  // Closes every session (Session.close() semantics): resolves when each subscriber's
  // done(reason) was delivered or failed.
  kj::Promise<void> close_all(const char* reason);
  void add_task(kj::Promise<void> task) { tasks_.add(kj::mv(task)); }

  // The core a new session's real-time loop pins itself to: 1 ... n-1 in turn (-1: headless,
  // no --pin, or a single core).
  int next_loop_cpu(bool headless);

  // /healthz (server/web.h) and the Agones health pings (server/agones.h): healthy while
  // every running real-time session held, since the previous probe with the same
  // `window` (or since it started), at least min_rate_fraction of its rate with at most
  // max_miss_fraction of its ticks missing their deadline. Paused and headless sessions
  // are not judged. Nor is an interval shorter than kMinJudgedSeconds or kMinJudgedTicks
  // periods of the session's rate (too few ticks: one miss would be a large fraction):
  // then the window's previous verdict on the session stands, and the next probe judges
  // the longer interval.
  static constexpr double kMinJudgedSeconds = 0.1;
  static constexpr double kMinJudgedTicks = 100;
  Probe health_probe(HealthWindow& window, double min_rate_fraction = 0.9, double max_miss_fraction = 0.05);

  // A session whose last reference went while its thread was still starting
  // (validating, reading files, building): cancelled and kept, without waiting for
  // it, until the thread has ended; then joined and freed.
  void adopt_starting(std::unique_ptr<Simulation> sim);
  // Sessions adopted that way whose thread has not ended yet (they count against
  // --max-sessions: a client cannot pile up builds by opening and leaving).
  size_t closing_sessions() const { return closing_.size(); }

 private:
  struct Closing;
  static kj::Promise<void> wait_until_started(Closing& closing);
  struct ErrorHandler : kj::TaskSet::ErrorHandler {
    void taskFailed(kj::Exception&& e) override;
  } error_handler_;
  int next_loop_core_ = 0;  // the next real-time loop's turn (next_loop_cpu)
  std::set<Closing*> closing_;  // declared before tasks_: a Closing (held by a task) erases itself
  kj::TaskSet tasks_{error_handler_};
};

// The bootstrap capability, one per connection (ServerContext::bootstrap_for_connection),
// and the ones authenticate() returns on it. `authenticated` false: only version() and
// authenticate() are served. RPC thread only.
class ServerImpl final : public wire::PalpateServer::Server {
 public:
  ServerImpl(ServerContext& ctx, std::shared_ptr<ConnectionState> connection, bool authenticated)
      : ctx_(ctx), connection_(std::move(connection)), authenticated_(authenticated) {}
  kj::Promise<void> version(VersionContext context) override;
  kj::Promise<void> openSession(OpenSessionContext context) override;
  kj::Promise<void> listScenes(ListScenesContext context) override;
  kj::Promise<void> attach(AttachContext context) override;
  kj::Promise<void> authenticate(AuthenticateContext context) override;

 private:
  void check_authenticated(const char* method) const;
  ServerContext& ctx_;
  std::shared_ptr<ConnectionState> connection_;
  bool authenticated_;
};

}  // namespace palpate::server
