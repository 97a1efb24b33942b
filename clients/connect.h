#pragma once
// A client's connection to palpate-server over TCP, plain or TLS, with the connection-time
// access token (docs/protocol.md, "Security model"): the one way the project's C++ clients
// connect, so that each of them speaks to a server started with --tls-cert or
// --access-token-file the same way.
//
//   ServerConnection c({.address = "host:7420", .tls_ca_file = "ca.pem", .access_token = token});
//   auto server = c.server();               // authenticated when a token was given
//   server.versionRequest().send().wait(c.wait_scope());
#include <cstdint>
#include <string>

#include <capnp/message.h>
#include <capnp/rpc-twoparty.h>
#include <kj/async-io.h>
#include <kj/compat/tls.h>

#include "protocol/palpate.capnp.h"

namespace palpate::client {

struct ConnectOptions {
  std::string address = "127.0.0.1:7420";  // HOST:PORT (a HOST alone takes port 7420)
  std::string tls_ca_file;                 // PEM certificates to trust: the connection is TLS; empty: plain TCP
  std::string tls_server_name;             // the name the server's certificate must carry; empty: HOST
  std::string access_token;                // presented with PalpateServer.authenticate; empty: none
  uint64_t traversal_limit_words = 256ull * 1024 * 1024;  // the largest message this client reads
};

// The access token in a file (one line; surrounding white space dropped), or
// std::invalid_argument naming the file.
std::string read_token_file(const std::string& file);

class ServerConnection {
 public:
  // Connects (and, with TLS, shakes hands; with a token, authenticates), or throws
  // kj::Exception / std::invalid_argument with the reason. This one sets up the thread's
  // event loop (a thread has one: a second connection on it takes the first's `io`).
  explicit ServerConnection(const ConnectOptions& options);
  // On an event loop the thread already has.
  ServerConnection(const ConnectOptions& options, kj::AsyncIoContext& io);
  ServerConnection(const ServerConnection&) = delete;
  ServerConnection& operator=(const ServerConnection&) = delete;
  ~ServerConnection();

  wire::PalpateServer::Client server() { return server_; }
  kj::WaitScope& wait_scope() { return io_.waitScope; }
  kj::Timer& timer() { return io_.provider->getTimer(); }
  kj::AsyncIoProvider& io_provider() { return *io_.provider; }
  kj::AsyncIoContext& io() { return io_; }

 private:
  void connect(const ConnectOptions& options);
  kj::Own<kj::AsyncIoContext> own_io_;  // the first constructor's
  kj::AsyncIoContext& io_;
  kj::Own<kj::TlsCertificate> ca_;
  kj::Own<kj::TlsContext> tls_;
  kj::Own<kj::AsyncIoStream> stream_;
  kj::Own<capnp::TwoPartyVatNetwork> network_;
  kj::Own<capnp::RpcSystem<capnp::rpc::twoparty::VatId>> rpc_;
  wire::PalpateServer::Client server_;
};

}  // namespace palpate::client
