#pragma once
// The RPC side of the server (runs on the KJ event-loop thread only):
// ServerImpl (bootstrap), SessionImpl (one Simulation each), SubscriptionImpl.
#include <cstdint>
#include <filesystem>
#include <list>
#include <map>
#include <memory>
#include <set>
#include <string>

#include <kj/async-io.h>

#include "protocol/palpate.capnp.h"
#include "server/requests.h"
#include "server/sim_loop.h"

namespace palpate::server {

class SessionImpl;

// Shared by every connection: options, the live sessions (for shutdown) and a
// TaskSet for fire-and-forget calls.
struct ServerContext {
  ServerContext(kj::AsyncIoContext& io, ServerOptions options);
  kj::AsyncIoContext& io;
  ServerOptions options;
  std::map<uint32_t, SessionImpl*> sessions;  // by id
  uint32_t next_subscriber_id = 1;
  uint32_t next_session_id = 1;

  // Stops every simulation thread (before the event loop goes away).
  void stop_all();
  void add_task(kj::Promise<void> task) { tasks_.add(kj::mv(task)); }

 private:
  struct ErrorHandler : kj::TaskSet::ErrorHandler {
    void taskFailed(kj::Exception&& e) override;
  } error_handler_;
  kj::TaskSet tasks_{error_handler_};
};

class ServerImpl final : public wire::PalpateServer::Server {
 public:
  explicit ServerImpl(ServerContext& ctx) : ctx_(ctx) {}
  kj::Promise<void> version(VersionContext context) override;
  kj::Promise<void> openSession(OpenSessionContext context) override;
  kj::Promise<void> listScenes(ListScenesContext context) override;
  kj::Promise<void> attach(AttachContext context) override;

 private:
  ServerContext& ctx_;
};

}  // namespace palpate::server
