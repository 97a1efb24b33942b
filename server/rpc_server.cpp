// The server on the RPC thread (server/rpc_server.h): ServerContext, what every connection
// shares, and ServerImpl, the bootstrap capability (version, authenticate, listScenes,
// openSession, attach). The sessions themselves are server/session.h.
#include "server/rpc_server.h"

#include <map>
#include <stdexcept>
#include <string>
#include <thread>

#include <kj/debug.h>
#include <spdlog/spdlog.h>

#include "server/session.h"

namespace palpate::server {

// ---------------------------------------------------------------------------
// ServerContext

namespace {
kj::Promise<void> beat(kj::Timer& timer, RpcHeartbeat& heartbeat) {
  heartbeat.last_ns.store(now_ns(), std::memory_order_relaxed);
  return timer.afterDelay(RpcHeartbeat::kPeriodNs * kj::NANOSECONDS).then([&timer, &heartbeat]() {
    return beat(timer, heartbeat);
  });
}
}  // namespace

ServerContext::ServerContext(kj::AsyncIoContext& io_, ServerOptions options_)
    : io(io_), options(std::move(options_)) {
  tasks_.add(beat(io.provider->getTimer(), heartbeat));
}

void ServerContext::ErrorHandler::taskFailed(kj::Exception&& e) {
  spdlog::debug("task ended: {}", e.getDescription().cStr());
}

// A cancelled session still starting, held by its task in tasks_ until the thread ends.
struct ServerContext::Closing {
  Closing(ServerContext& c, std::unique_ptr<Simulation> s) : ctx(c), sim(std::move(s)) {
    wake = ctx.io.lowLevelProvider->wrapInputFd(
        sim->wake_fd(), kj::LowLevelAsyncIoProvider::ALREADY_CLOEXEC | kj::LowLevelAsyncIoProvider::ALREADY_NONBLOCK);
    ctx.closing_.insert(this);  // last: the destructor runs only for a complete object
  }
  ~Closing() noexcept(false) {
    wake = nullptr;  // before the Simulation closes the eventfd
    ctx.closing_.erase(this);
    sim->stop();     // the thread has ended its start (or does so now): a short join
  }
  ServerContext& ctx;
  std::unique_ptr<Simulation> sim;
  kj::Own<kj::AsyncInputStream> wake;
  uint8_t buffer[8] = {};
};

// Resolves once the thread left Phase::starting (it writes the eventfd after setting
// the phase, so the phase is checked before each wait).
kj::Promise<void> ServerContext::wait_until_started(Closing& closing) {
  if (closing.sim->phase() != Phase::starting) return kj::READY_NOW;
  return closing.wake->tryRead(closing.buffer, 1, sizeof closing.buffer).then([&closing](size_t) {
    return wait_until_started(closing);
  });
}

void ServerContext::adopt_starting(std::unique_ptr<Simulation> sim) {
  sim->cancel();
  auto closing = kj::heap<Closing>(*this, std::move(sim));
  Closing& ref = *closing;
  tasks_.add(wait_until_started(ref).attach(kj::mv(closing)));
}

// ---------------------------------------------------------------------------
// ServerImpl

kj::Promise<void> ServerImpl::version(VersionContext context) {
  context.getResults().setProtocolVersion(wire::PROTOCOL_VERSION);
  context.getResults().setServer("palpate-server 0.1");
  return kj::READY_NOW;
}

void ServerImpl::check_authenticated(const char* method) const {
  if (!authenticated_)
    fail(std::string(method) +
         ": this server requires an access token: call PalpateServer.authenticate(accessToken) first and use the "
         "capability it returns (palpate-server --access-token-file)");
}

kj::Promise<void> ServerImpl::authenticate(AuthenticateContext context) {
  const std::string& expected = ctx_.options.access_token;
  if (!expected.empty()) {
    ctx_.check_guesses_left(*connection_, "authenticate");
    const auto token = context.getParams().getAccessToken();
    if (!tokens_equal(std::string_view(token.begin(), token.size()), expected))
      return ctx_.refuse_guess(*connection_, "authenticate: accessToken: not this server's access token");
  }
  context.getResults().setServer(kj::heap<ServerImpl>(ctx_, connection_, true));
  return kj::READY_NOW;
}

kj::Promise<void> ServerImpl::listScenes(ListScenesContext context) {
  check_authenticated("listScenes");
  const auto names = scene_names(ctx_.options.scene_dir);
  auto list = context.getResults().initNames(static_cast<unsigned>(names.size()));
  for (unsigned k = 0; k < names.size(); ++k) list.set(k, names[k]);
  return kj::READY_NOW;
}

// Without a token: a read-only view (SessionViewImpl). With the session's control token: its
// control capability. An unknown id or a wrong token: refused after a delay, and counted.
kj::Promise<void> ServerImpl::attach(AttachContext context) {
  check_authenticated("attach");
  ctx_.check_guesses_left(*connection_, "attach");
  const uint32_t id = context.getParams().getSessionId();
  const auto token = context.getParams().getControlToken();
  const auto it = ctx_.sessions.find(id);
  if (it == ctx_.sessions.end())
    return ctx_.refuse_guess(*connection_, "attach: sessionId: no live session " + std::to_string(id));
  SessionImpl& session = *it->second;
  const bool control = token.size() > 0;
  if (control && !tokens_equal(std::string_view(token.begin(), token.size()), session.control_token()))
    return ctx_.refuse_guess(*connection_, "attach: controlToken: not the control token of session " +
                                               std::to_string(id) + " (leave it empty for a read-only view)");
  wire::Session::Client cap = control ? session.self() : read_only_view(session.link(), id);
  context.allowCancellation();  // waiting for a start holds nothing worth finishing
  auto ready = session.when_ready();
  return ready.then([context, cap = kj::mv(cap), link = session.link(), control]() mutable {
    if (link->session == nullptr) fail("attach: the session ended while it was starting");
    auto results = context.getResults();
    link->session->fill_info(results.initInfo(), control);
    results.setSession(kj::mv(cap));
  });
}

// Never blocks the event loop: only the cheap checks run here; the scene is
// validated, its files read and its model built on the session's thread, and the
// call resolves (or rejects with that thread's message) when it is done.
kj::Promise<void> ServerImpl::openSession(OpenSessionContext context) {
  check_authenticated("openSession");
  // Closed sessions whose capabilities are still held count against no limit.
  size_t running = ctx_.closing_sessions();
  for (const auto& [id, s] : ctx_.sessions) running += s->closed() ? 0 : 1;
  if (static_cast<int>(running) >= ctx_.options.max_sessions)
    fail("openSession: the server already runs " + std::to_string(running) +
         " sessions, its limit (palpate-server --max-sessions " + std::to_string(ctx_.options.max_sessions) + ")");
  if (connection_->sessions_open >= ctx_.options.max_sessions_per_connection)
    fail("openSession: this connection already has " + std::to_string(connection_->sessions_open) +
         " live sessions, the limit per connection (palpate-server --max-sessions-per-connection " +
         std::to_string(ctx_.options.max_sessions_per_connection) + "): close one first");
  OpenPlan plan = plan_session(context.getParams().getRequest(), ctx_.options);
  context.allowCancellation();  // a caller that cancels or disconnects drops the start (below)

  auto impl = kj::heap<SessionImpl>(ctx_, std::move(plan), connection_);
  SessionImpl& session = *impl;
  wire::Session::Client cap = kj::mv(impl);
  auto ready = session.when_ready();
  // If the caller goes meanwhile, this promise is dropped with `cap`: the session,
  // still starting, is cancelled and handed to ctx_.adopt_starting (no wait here).
  return ready.then([context, cap = kj::mv(cap), &session]() mutable {
    auto results = context.getResults();
    session.fill_info(results.initInfo(), true);
    results.setControlToken(session.control_token());
    results.setSession(kj::mv(cap));
  });
}

capnp::Capability::Client ServerContext::bootstrap_for_connection() {
  return kj::heap<ServerImpl>(*this, std::make_shared<ConnectionState>(), options.access_token.empty());
}

uint32_t ServerContext::new_session_id() const {
  uint32_t id = random_session_id();
  while (sessions.count(id) != 0) id = random_session_id();
  return id;
}

void ServerContext::check_guesses_left(const ConnectionState& connection, const char* method) const {
  if (connection.wrong_tokens >= options.max_wrong_tokens)
    fail(std::string(method) + ": this connection was refused " + std::to_string(connection.wrong_tokens) +
         " tokens or session ids, its limit (palpate-server --max-wrong-tokens " +
         std::to_string(options.max_wrong_tokens) + "): it may try no more");
}

kj::Promise<void> ServerContext::refuse_guess(ConnectionState& connection, std::string message) {
  ++connection.wrong_tokens;
  spdlog::info("refused: {}", message);  // names the method and the id, never a token
  return io.provider->getTimer()
      .afterDelay(options.wrong_token_delay_ms * kj::MILLISECONDS)
      .then([message = std::move(message)]() { fail(message); });
}

void ServerContext::stop_all() {
  for (auto& [id, s] : sessions) s->stop();
  for (Closing* c : closing_) c->sim->stop();
}

int ServerContext::next_loop_cpu(bool headless) {
  const int cores = static_cast<int>(std::thread::hardware_concurrency());
  if (headless || !options.pin_threads || cores < 2) return -1;
  const int cpu = 1 + next_loop_core_ % (cores - 1);  // core 0 keeps the RPC thread and the workers
  ++next_loop_core_;
  return cpu;
}

Probe ServerContext::health_probe(HealthWindow& window, double min_rate_fraction, double max_miss_fraction) {
  Probe probe;
  std::map<uint32_t, HealthWindow::Sample> samples;
  int realtime = 0;
  for (const auto& [id, s] : sessions) {
    const Simulation& sim = s->simulation();
    if (s->closed() || sim.config().headless || sim.phase() != Phase::ready || sim.status().paused) continue;
    ++realtime;
    const SimCounters c = sim.counters();
    HealthWindow::Sample now{c.ticks, c.elapsed_s, c.deadline_misses, ""};
    // Over the time since this window's previous probe (or since the session started).
    HealthWindow::Sample before{};
    const auto it = window.samples_.find(id);
    if (it != window.samples_.end()) before = it->second;
    const double seconds = now.elapsed_s - before.elapsed_s, target = sim.config().rate_hz;
    if (seconds < kMinJudgedSeconds || seconds * target < kMinJudgedTicks) {
      // Too short to judge: the previous verdict stands; the longer interval is judged next time.
      if (it != window.samples_.end()) samples[id] = before;
      now.failure = before.failure;
    } else {
      const double ticks = static_cast<double>(now.ticks - before.ticks);
      const double rate = ticks / seconds;
      const double misses =
          ticks > 0 ? static_cast<double>(now.deadline_misses - before.deadline_misses) / ticks : 1.0;
      if (rate < min_rate_fraction * target || misses > max_miss_fraction)
        now.failure = "session " + std::to_string(id) + ": " + std::to_string(rate) + " Hz of " +
                      std::to_string(target) + " Hz, deadline misses " + std::to_string(100.0 * misses) + " %; ";
      samples[id] = now;
    }
    if (!now.failure.empty()) {
      probe.ok = false;
      probe.detail += now.failure;
    }
  }
  window.samples_ = std::move(samples);
  if (probe.ok) probe.detail = "ok: " + std::to_string(realtime) + " real-time session(s) hold their rate";
  return probe;
}

kj::Promise<void> ServerContext::close_all(const char* reason) {
  kj::Vector<kj::Promise<void>> closing;
  for (auto& [id, s] : sessions) closing.add(s->close_session(reason));
  return kj::joinPromises(closing.releaseAsArray());
}

}  // namespace palpate::server
