#pragma once
// One session on the RPC thread: SessionImpl (the owner's control capability; its
// Simulation, sim_loop.h, runs on a thread of its own), its subscriptions and its read-only
// views (attach() without the control token). Streaming policy (docs/protocol.md, "Flow
// control"): per subscriber {inFlight, nextDue, interval}. When the simulation publishes
// (eventfd wake-up), the newest frame goes to every subscriber that is due and has nothing
// in flight; a due subscriber that still has a frame in flight skips this one (drop-newest)
// and it is counted. Nothing queues: the triple buffer holds only the newest frame, so a
// slow viewer costs the loop and the other subscribers nothing.
#include <cstdint>
#include <list>
#include <memory>
#include <string>
#include <vector>

#include <kj/async-io.h>

#include "protocol/palpate.capnp.h"
#include "server/access.h"
#include "server/frames.h"
#include "server/requests.h"
#include "server/sim_loop.h"

namespace palpate::server {

struct ServerContext;
class SessionImpl;

// How read-only views and subscriptions reach their session without keeping it alive: the
// session clears `session` when it ends. RPC thread only.
struct SessionLink {
  SessionImpl* session;
};

class SessionImpl final : public wire::Session::Server {
 public:
  // Starts the session's thread on the plan; the scene is resolved and validated there.
  // `opener`: the connection that opened it (its count of live sessions).
  SessionImpl(ServerContext& ctx, OpenPlan plan, std::shared_ptr<ConnectionState> opener);

  ~SessionImpl() noexcept(false);

  // Resolves once the model is built; rejects with the error of the start (a scene
  // error, a file refused, a failed build) as the client's message.
  kj::Promise<void> when_ready();

  void stop() { sim_->stop(); }
  wire::Session::Client self() { return thisCap(); }
  // Gives the opener's connection its slot back (--max-sessions-per-connection), once.
  void release_slot();
  const std::string& control_token() const { return control_token_; }
  const std::shared_ptr<SessionLink>& link() const { return link_; }
  const Simulation& simulation() const { return *sim_; }
  bool closed() const { return closed_; }

  // Every subscriber gets done(reason) and is removed; resolves when each done() was
  // delivered or failed (a vanished client).
  kj::Promise<void> end_subscriptions(const char* reason);

  // Session.close() and the server's shutdown: the loop stops, subscribers are told.
  kj::Promise<void> close_session(const char* reason);

  static kj::Promise<void> send_done(wire::FrameSink::Client& sink, const char* reason);

  // `control`: for a control reference (SessionInfo.control), else a read-only view's.
  void fill_info(wire::SessionInfo::Builder info, bool control);

  // --- Session methods -----------------------------------------------------

  kj::Promise<void> setForce(SetForceContext context) override;
  kj::Promise<void> setForceVector(SetForceVectorContext context) override;
  kj::Promise<void> setPosition(SetPositionContext context) override;
  kj::Promise<void> setCoupling(SetCouplingContext context) override;
  kj::Promise<void> close(CloseContext) override;
  kj::Promise<void> reset(ResetContext context) override;
  kj::Promise<void> pause(PauseContext context) override;
  kj::Promise<void> resume(ResumeContext context) override;
  kj::Promise<void> subscribe(SubscribeContext context) override;
  kj::Promise<void> step(StepContext context) override;
  kj::Promise<void> stats(StatsContext context) override;
  kj::Promise<void> status(StatusContext context) override;
  kj::Promise<void> info(InfoContext context) override;

  // The subscriber leaves (its handle released, or cancel() with `reason`: then its
  // sink gets done(reason) after the frames already sent).
  void unsubscribe(uint32_t id, const char* reason = nullptr);

 private:
  struct Subscriber {
    uint32_t id;
    wire::FrameSink::Client sink;
    double rate_hz;
    int64_t interval_ns;
    FieldRequest fields;
    bool in_flight = false;
    bool dead = false;
    int64_t next_due_ns = 0;
    uint64_t sent = 0, dropped = 0;
    kj::Promise<void> pending = nullptr;
  };

  kj::Promise<void> watch();

  static std::unique_ptr<Simulation> start(OpenPlan& plan, ServerContext& ctx);

  // Every method of a closed session fails (close() itself is idempotent).
  void check_open(const char* method);

  void check_phase();

  void on_wake();

  void stream(const Snapshot& frame, const HapticSample* render = nullptr);

  void update_wanted();

  // surfaceOnly needs a surface (SessionInfo.surfaceVertices): refused, naming the field, without.
  void check_fields(const char* field, const FieldRequest& fields);

  // The frame's derived fields that `want` asks for, computed now unless they already were for
  // this frame; null when it asks for none or the frame has no double-precision positions yet
  // (a subscriber newer than the frame).
  const DerivedFields* derived_for(const Snapshot& s, const FieldRequest& want);

  friend class SubscriptionImpl;
  // All members: RPC thread only (the Simulation's own members say which of its
  // parts the session's thread touches).
  ServerContext& ctx_;
  uint32_t id_;
  std::string control_token_;                // attach() with it gives a control reference (server/access.h)
  std::shared_ptr<ConnectionState> opener_;  // the connection that opened it (sessions_open)
  std::shared_ptr<SessionLink> link_;        // cleared when the session ends
  bool holds_slot_ = true;                   // counted in opener_->sessions_open
  uint32_t logged_blow_ups_ = 0;   // recoveries already logged (on_wake)
  int64_t logged_drops_ = 0;       // dropped refocuses already logged (on_wake)
  std::unique_ptr<Simulation> sim_;  // declared before the watchers: destroyed after them
  kj::Own<kj::AsyncInputStream> wake_;
  kj::Promise<void> wake_loop_ = nullptr;
  uint8_t wake_buffer_[8] = {};
  Phase phase_ = Phase::starting;  // as last seen on the RPC thread
  std::string error_;              // phase_ == failed
  double force_limit_ = 0.0;       // N, once phase_ == ready
  CouplingOptions coupling_;       // the coupling in effect (SessionInfo.coupling), once ready
  bool closed_ = false;            // Session.close() or the server's shutdown
  std::vector<uint32_t> surface_vertices_;  // SessionInfo.surfaceVertices, once ready
  DerivedFields derived_;                    // of the newest frame that needed them
  kj::Vector<kj::Own<kj::PromiseFulfiller<void>>> ready_waiters_;
  kj::Own<kj::PromiseFulfiller<void>> job_;
  std::list<Subscriber> subscribers_;
};

// A read-only view of the session behind `link` (attach() without the control token).
wire::Session::Client read_only_view(std::shared_ptr<SessionLink> link, uint32_t id);

}  // namespace palpate::server
