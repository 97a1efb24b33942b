#pragma once
// A Cap'n Proto client of palpate-server over WebSocket (ws://127.0.0.1:PORT/rpc) on a
// thread's event loop, built from kj-http's WebSocket client and capnp's
// WebSocketMessageStream, as a browser's connection is.
#include <random>
#include <string>

#include <capnp/compat/websocket-rpc.h>
#include <capnp/message.h>
#include <capnp/rpc-twoparty.h>
#include <kj/async-io.h>
#include <kj/compat/http.h>

#include "protocol/palpate.capnp.h"

namespace palpate::test {

class Entropy final : public kj::EntropySource {
 public:
  void generate(kj::ArrayPtr<kj::byte> buffer) override {
    for (auto& b : buffer) b = static_cast<kj::byte>(rng_());
  }

 private:
  std::mt19937 rng_{std::random_device{}()};
};

struct WsRpcConnection {
  // `origin`: the Origin header to send (none when empty). status is the upgrade's (101 when
  // accepted); server stays null when it was refused.
  WsRpcConnection(kj::AsyncIoContext& io, int web_port, const std::string& origin = "") {
    kj::HttpHeaderTable::Builder builder;
    const kj::HttpHeaderId origin_id = builder.add("Origin");
    table = builder.build();
    kj::HttpClientSettings settings;
    settings.entropySource = entropy;
    http = kj::newHttpClient(io.provider->getTimer(), *table, io.provider->getNetwork(), nullptr, settings);
    kj::HttpHeaders headers(*table);
    if (!origin.empty()) headers.set(origin_id, origin);
    const std::string url = "http://127.0.0.1:" + std::to_string(web_port) + "/rpc";
    auto response = http->openWebSocket(url, headers).wait(io.waitScope);
    status = response.statusCode;
    if (!response.webSocketOrBody.is<kj::Own<kj::WebSocket>>()) return;
    socket = kj::mv(response.webSocketOrBody.get<kj::Own<kj::WebSocket>>());
    stream = kj::heap<capnp::WebSocketMessageStream>(*socket);
    network = kj::heap<capnp::TwoPartyVatNetwork>(*stream, capnp::rpc::twoparty::Side::CLIENT);
    rpc = kj::heap(capnp::makeRpcClient(*network));
    capnp::MallocMessageBuilder vat;
    auto host = vat.initRoot<capnp::rpc::twoparty::VatId>();
    host.setSide(capnp::rpc::twoparty::Side::SERVER);
    server = rpc->bootstrap(host).castAs<wire::PalpateServer>();
  }

  Entropy entropy;
  kj::Own<kj::HttpHeaderTable> table;
  kj::Own<kj::HttpClient> http;
  unsigned status = 0;
  kj::Own<kj::WebSocket> socket;
  kj::Own<capnp::WebSocketMessageStream> stream;
  kj::Own<capnp::TwoPartyVatNetwork> network;
  kj::Own<capnp::RpcSystem<capnp::rpc::twoparty::VatId>> rpc;
  wire::PalpateServer::Client server = nullptr;
};

}  // namespace palpate::test
