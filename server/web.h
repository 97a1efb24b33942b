#pragma once
// The server's web listener (palpate-server --http ADDR:PORT): one kj-http server that
//   - upgrades GET /rpc to a WebSocket and runs the same Cap'n Proto RPC protocol over it
//     as the TCP listener (server/connection.h): the browser viewer and any WebSocket
//     client get the same PalpateServer bootstrap, the same validation and the same
//     flow control as TCP clients;
//   - serves the viewer's static files (clients/viewer, built into --web-root) for GET
//     and HEAD: "/" is index.html; only plain names [A-Za-z0-9._-] separated by '/' are
//     looked up, never outside the root;
//   - answers GET /healthz and /readyz for orchestrators (plain Kubernetes probes).
// RPC thread only (it runs on the KJ event loop). docs/protocol.md, "WebSocket".
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <capnp/capability.h>
#include <kj/async-io.h>
#include <kj/compat/http.h>

#include "server/connection.h"

namespace palpate::server {

struct WebOptions {
  std::filesystem::path root;                // the viewer's built files; empty: none served
  std::vector<std::string> allowed_origins;  // Origins accepted on /rpc besides the page's own
                                             // (http://HOST of the request); "*" accepts any
};

// What /healthz and /readyz report: ok selects 200 or 503, detail is the body's text.
struct Probe {
  bool ok = true;
  std::string detail;
};

struct WebProbes {
  std::function<Probe()> ready;   // /readyz
  std::function<Probe()> health;  // /healthz
};

// Whether a WebSocket upgrade from `origin` (the Origin header, absent for non-browser
// clients) may be accepted by a server reached as `host` (the Host header).
// Same-origin pages (http://HOST or https://HOST) always may; others only when listed
// in `allowed` (or "*" is). Requests without an Origin are not from a browser page and
// are accepted like TCP connections.
bool origin_allowed(const kj::Maybe<kj::StringPtr>& origin, const kj::Maybe<kj::StringPtr>& host,
                    const std::vector<std::string>& allowed);

// The file under `root` that the URL path names, or an empty path when it names none
// (a query string and fragment are ignored; "" and "/" name index.html; any segment
// that is empty, "." or "..", or any character outside [A-Za-z0-9._-/] names none).
std::filesystem::path static_file_for(const std::filesystem::path& root, std::string_view url);

// Content-Type for a file name by its extension (text/html, application/javascript, ...).
const char* content_type_for(const std::filesystem::path& file);

// Runs the web listener until the returned promise is dropped. Connections accepted are
// prepared as on the TCP listener (prepare_accepted: socket options, TLS), and each
// WebSocket RPC connection gets its own bootstrap (accept.bootstrap).
class WebServer {
 public:
  WebServer(kj::Timer& timer, WebOptions options, WebProbes probes, AcceptOptions accept);
  ~WebServer();
  kj::Promise<void> listen(kj::ConnectionReceiver& listener);

 private:
  class Service;
  kj::Promise<void> accept_loop(kj::ConnectionReceiver& listener);
  kj::Timer& timer_;
  AcceptOptions accept_;
  kj::Own<kj::HttpHeaderTable> table_;
  kj::Own<Service> service_;
  kj::Own<kj::HttpServer> http_;
  kj::Own<kj::TaskSet> connections_;  // one listenHttp() per accepted connection; destroyed first
};

}  // namespace palpate::server
