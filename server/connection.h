#pragma once
// One client connection of either transport: a TCP byte stream (capnp's own framing)
// or a WebSocket (one capnp message per binary WebSocket message, capnp's
// WebSocketMessageStream), each carrying the same two-party RPC system with the same
// bootstrap capability. Nothing of the session logic depends on the transport: both
// end in the one ServerImpl (server/session.h). RPC thread only.
#include <capnp/compat/websocket-rpc.h>
#include <capnp/message.h>
#include <capnp/rpc-twoparty.h>
#include <kj/async-io.h>
#include <kj/compat/http.h>

namespace palpate::server {

// The limits every connection reads with (docs/protocol.md, "Limits").
inline capnp::ReaderOptions rpc_reader_options() {
  capnp::ReaderOptions o;
  o.traversalLimitInWords = 64 * 1024 * 1024;  // 512 MiB: inline scenes with node lists (TCP)
  return o;
}
inline constexpr size_t kRpcFlowLimitWords = 1 << 20;  // words of incoming calls in flight per connection

class RpcConnection {
 public:
  // TCP: the stream carries capnp's segment framing.
  RpcConnection(kj::Own<kj::AsyncIoStream> stream, capnp::Capability::Client bootstrap)
      : stream_(kj::mv(stream)),
        network_(kj::heap<capnp::TwoPartyVatNetwork>(*stream_, capnp::rpc::twoparty::Side::SERVER,
                                                     rpc_reader_options())),
        rpc_(capnp::makeRpcServer(*network_, kj::mv(bootstrap))) {
    rpc_.setFlowLimit(kRpcFlowLimitWords);
  }
  // WebSocket: each capnp message is one binary message of at most
  // kj::WebSocket::SUGGESTED_MAX_MESSAGE_SIZE (1 MiB, enforced by kj when receiving;
  // a larger one ends the connection).
  RpcConnection(kj::Own<kj::WebSocket> websocket, capnp::Capability::Client bootstrap)
      : websocket_(kj::mv(websocket)),
        messages_(kj::heap<capnp::WebSocketMessageStream>(*websocket_)),
        network_(kj::heap<capnp::TwoPartyVatNetwork>(*messages_, capnp::rpc::twoparty::Side::SERVER,
                                                     rpc_reader_options())),
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
