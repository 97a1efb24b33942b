#pragma once
// One client connection of either transport: a TCP byte stream (capnp's own framing)
// or a WebSocket (one capnp message per binary WebSocket message, capnp's
// WebSocketMessageStream), each carrying the same two-party RPC system with the same
// bootstrap capability. Nothing of the session logic depends on the transport: both
// end in the one ServerImpl (server/rpc_server.h). RPC thread only.
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

#include <functional>

#include <capnp/compat/websocket-rpc.h>
#include <capnp/message.h>
#include <capnp/rpc-twoparty.h>
#include <kj/async-io.h>
#include <kj/compat/http.h>
#include <kj/compat/tls.h>

namespace palpate::server {

// The limits every connection reads with (docs/protocol.md, "Limits"): a message over
// max_message_bytes ends its connection (palpate-server --max-message-bytes).
inline capnp::ReaderOptions rpc_reader_options(size_t max_message_bytes) {
  capnp::ReaderOptions o;
  o.traversalLimitInWords = max_message_bytes / sizeof(capnp::word);
  return o;
}
inline constexpr size_t kDefaultMaxMessageBytes = 16u << 20;  // 16 MiB: a scene with its overrides fits many times
inline constexpr size_t kRpcFlowLimitWords = 1 << 20;  // words of incoming calls in flight per connection

// What both listeners (TCP and --http) do with a connection they accept.
struct AcceptOptions {
  int sndbuf = 256 * 1024;  // SO_SNDBUF, bounding how far a slow reader falls behind; 0 keeps the system's
  size_t max_message_bytes = kDefaultMaxMessageBytes;
  kj::TlsContext* tls = nullptr;  // --tls-cert/--tls-key: every connection is TLS (null: plain TCP)
  std::function<capnp::Capability::Client()> bootstrap;  // a new connection's PalpateServer
};

// The accepted socket's options (SO_SNDBUF, TCP_NODELAY, SO_KEEPALIVE), then, with TLS,
// the handshake (bounded by the TLS context's accept timeout): the stream to serve.
inline kj::Promise<kj::Own<kj::AsyncIoStream>> prepare_accepted(kj::Own<kj::AsyncIoStream> stream,
                                                                const AcceptOptions& o) {
  if (o.sndbuf > 0) stream->setsockopt(SOL_SOCKET, SO_SNDBUF, &o.sndbuf, sizeof o.sndbuf);
  const int one = 1;
  stream->setsockopt(IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  stream->setsockopt(SOL_SOCKET, SO_KEEPALIVE, &one, sizeof one);
  if (o.tls == nullptr) return kj::mv(stream);
  return o.tls->wrapServer(kj::mv(stream));
}

class RpcConnection {
 public:
  // TCP: the stream carries capnp's segment framing.
  RpcConnection(kj::Own<kj::AsyncIoStream> stream, capnp::Capability::Client bootstrap, size_t max_message_bytes)
      : stream_(kj::mv(stream)),
        network_(kj::heap<capnp::TwoPartyVatNetwork>(*stream_, capnp::rpc::twoparty::Side::SERVER,
                                                     rpc_reader_options(max_message_bytes))),
        rpc_(capnp::makeRpcServer(*network_, kj::mv(bootstrap))) {
    rpc_.setFlowLimit(kRpcFlowLimitWords);
  }
  // WebSocket: each capnp message is one binary message of at most
  // kj::WebSocket::SUGGESTED_MAX_MESSAGE_SIZE (1 MiB, enforced by kj when receiving;
  // a larger one ends the connection), and of at most max_message_bytes when smaller.
  RpcConnection(kj::Own<kj::WebSocket> websocket, capnp::Capability::Client bootstrap, size_t max_message_bytes)
      : websocket_(kj::mv(websocket)),
        messages_(kj::heap<capnp::WebSocketMessageStream>(*websocket_)),
        network_(kj::heap<capnp::TwoPartyVatNetwork>(*messages_, capnp::rpc::twoparty::Side::SERVER,
                                                     rpc_reader_options(max_message_bytes))),
        rpc_(capnp::makeRpcServer(*network_, kj::mv(bootstrap))) {
    rpc_.setFlowLimit(kRpcFlowLimitWords);
  }
  // Resolves when the peer has gone (or the transport failed).
  kj::Promise<void> on_disconnect() { return network_->onDisconnect(); }

 private:
  // Declared in construction order (and destroyed in reverse): the transport, then the
  // network over it, then the RPC system over the network.
  kj::Own<kj::AsyncIoStream> stream_;
  kj::Own<kj::WebSocket> websocket_;
  kj::Own<capnp::WebSocketMessageStream> messages_;
  kj::Own<capnp::TwoPartyVatNetwork> network_;
  capnp::RpcSystem<capnp::rpc::twoparty::VatId> rpc_;
};

}  // namespace palpate::server
