#include "server/web.h"

#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

#include <algorithm>
#include <fstream>
#include <iterator>

#include <spdlog/spdlog.h>

#include "server/connection.h"

namespace palpate::server {

namespace fs = std::filesystem;

bool origin_allowed(const kj::Maybe<kj::StringPtr>& origin, const kj::Maybe<kj::StringPtr>& host,
                    const std::vector<std::string>& allowed) {
  KJ_IF_MAYBE (o, origin) {
    const std::string_view value(o->begin(), o->size());
    for (const std::string& a : allowed)
      if (a == "*" || a == value) return true;
    KJ_IF_MAYBE (h, host) {
      const std::string_view hv(h->begin(), h->size());
      for (const std::string_view scheme : {"http://", "https://"})
        if (value.size() == scheme.size() + hv.size() && value.substr(0, scheme.size()) == scheme &&
            value.substr(scheme.size()) == hv)
          return true;
    }
    return false;
  }
  return true;  // no Origin: not a browser page
}

fs::path static_file_for(const fs::path& root, std::string_view url) {
  const size_t end = url.find_first_of("?#");
  std::string_view path = url.substr(0, end);
  if (path.empty() || path == "/") return root / "index.html";
  if (path.front() != '/') return {};
  path.remove_prefix(1);
  fs::path file = root;
  size_t start = 0;
  while (start <= path.size()) {
    const size_t slash = path.find('/', start);
    const std::string_view segment = path.substr(start, slash == std::string_view::npos ? path.npos : slash - start);
    if (segment.empty() || segment == "." || segment == "..") return {};
    const bool plain = std::all_of(segment.begin(), segment.end(), [](char c) {
      return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' || c == '_' ||
             c == '-';
    });
    if (!plain) return {};
    file /= std::string(segment);
    if (slash == std::string_view::npos) break;
    start = slash + 1;
  }
  return file;
}

const char* content_type_for(const fs::path& file) {
  const std::string ext = file.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json" || ext == ".map") return "application/json";
  if (ext == ".png") return "image/png";
  if (ext == ".svg") return "image/svg+xml";
  if (ext == ".txt") return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

class WebServer::Service final : public kj::HttpService {
 public:
  Service(const kj::HttpHeaderTable& table, kj::HttpHeaderId origin, kj::HttpHeaderId cache_control,
          kj::HttpHeaderId nosniff, WebOptions options, WebProbes probes, const AcceptOptions& accept)
      : table_(table),
        origin_(origin),
        cache_control_(cache_control),
        nosniff_(nosniff),
        options_(std::move(options)),
        probes_(std::move(probes)),
        accept_(accept) {}

  kj::Promise<void> request(kj::HttpMethod method, kj::StringPtr url, const kj::HttpHeaders& headers,
                            kj::AsyncInputStream&, Response& response) override {
    std::string_view path(url.begin(), url.size());
    path = path.substr(0, path.find_first_of("?#"));
    if (headers.isWebSocket()) {
      if (path != "/rpc") return text(response, 404, "Not Found", "WebSocket RPC is at /rpc\n");
      if (!origin_allowed(headers.get(origin_), headers.get(kj::HttpHeaderId::HOST), options_.allowed_origins)) {
        KJ_IF_MAYBE (o, headers.get(origin_)) spdlog::info("WebSocket from origin {} refused", o->cStr());
        return text(response, 403, "Forbidden",
                    "this Origin may not open RPC sessions here (palpate-server --allow-origin)\n");
      }
      kj::HttpHeaders reply(table_);
      auto connection =
          kj::heap<RpcConnection>(response.acceptWebSocket(reply), accept_.bootstrap(), accept_.max_message_bytes);
      spdlog::debug("WebSocket RPC connection accepted");
      // The HTTP connection lives as long as this promise: until the peer goes.
      auto done = connection->on_disconnect();
      return done.attach(kj::mv(connection));
    }
    if (method != kj::HttpMethod::GET && method != kj::HttpMethod::HEAD)
      return text(response, 405, "Method Not Allowed", "GET or HEAD only\n");
    if (path == "/healthz" || path == "/readyz") {
      const auto& probe = path == "/healthz" ? probes_.health : probes_.ready;
      const Probe p = probe ? probe() : Probe{true, "ok"};
      return text(response, p.ok ? 200 : 503, p.ok ? "OK" : "Service Unavailable", p.detail + "\n");
    }
    if (options_.root.empty()) return text(response, 404, "Not Found", "no viewer is served here (--web-root)\n");
    const fs::path file = static_file_for(options_.root, path);
    std::error_code ec;
    if (file.empty() || !fs::is_regular_file(file, ec)) return text(response, 404, "Not Found", "not found\n");
    std::ifstream in(file, std::ios::binary);
    std::string body((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in && !in.eof()) return text(response, 500, "Internal Server Error", "cannot read the file\n");
    return send(response, method, 200, "OK", content_type_for(file), std::move(body));
  }

 private:
  kj::Promise<void> text(Response& response, unsigned status, kj::StringPtr reason, std::string body) {
    return send(response, kj::HttpMethod::GET, status, reason, "text/plain; charset=utf-8", std::move(body));
  }
  kj::Promise<void> send(Response& response, kj::HttpMethod method, unsigned status, kj::StringPtr reason,
                         const char* type, std::string body) {
    kj::HttpHeaders h(table_);
    h.set(kj::HttpHeaderId::CONTENT_TYPE, type);
    h.set(cache_control_, "no-cache");
    h.set(nosniff_, "nosniff");
    auto out = response.send(status, reason, h, static_cast<uint64_t>(body.size()));
    if (method == kj::HttpMethod::HEAD || body.empty()) return kj::READY_NOW;
    auto data = kj::heap<std::string>(std::move(body));
    auto written = out->write(data->data(), data->size());
    return written.attach(kj::mv(out), kj::mv(data));
  }

  const kj::HttpHeaderTable& table_;
  kj::HttpHeaderId origin_, cache_control_, nosniff_;
  WebOptions options_;
  WebProbes probes_;
  const AcceptOptions& accept_;  // the WebServer's
};

namespace {
struct LogEnded : kj::TaskSet::ErrorHandler {
  void taskFailed(kj::Exception&& e) override { spdlog::debug("web connection ended: {}", e.getDescription().cStr()); }
};
LogEnded log_ended;
}  // namespace

WebServer::WebServer(kj::Timer& timer, WebOptions options, WebProbes probes, AcceptOptions accept)
    : timer_(timer), accept_(std::move(accept)) {
  kj::HttpHeaderTable::Builder builder;
  const kj::HttpHeaderId origin = builder.add("Origin");
  const kj::HttpHeaderId cache_control = builder.add("Cache-Control");
  const kj::HttpHeaderId nosniff = builder.add("X-Content-Type-Options");
  table_ = builder.build();
  service_ = kj::heap<Service>(*table_, origin, cache_control, nosniff, std::move(options), std::move(probes),
                               accept_);
  http_ = kj::heap<kj::HttpServer>(timer_, *table_, *service_);
  connections_ = kj::heap<kj::TaskSet>(log_ended);
}

WebServer::~WebServer() = default;

kj::Promise<void> WebServer::listen(kj::ConnectionReceiver& listener) { return accept_loop(listener); }

kj::Promise<void> WebServer::accept_loop(kj::ConnectionReceiver& listener) {
  return listener.accept()
      .then(
          [this](kj::Own<kj::AsyncIoStream> stream) {
            // The handshake (with TLS) runs in the connection's task, not in the accept loop.
            connections_->add(prepare_accepted(kj::mv(stream), accept_).then([this](kj::Own<kj::AsyncIoStream> s) {
              return http_->listenHttp(kj::mv(s));
            }));
            return kj::Promise<void>(kj::READY_NOW);
          },
          [this](kj::Exception&& e) {  // e.g. out of descriptors: back off, keep serving
            spdlog::warn("web accept failed: {}", e.getDescription().cStr());
            return timer_.afterDelay(10 * kj::MILLISECONDS);
          })
      .then([this, &listener]() { return accept_loop(listener); });
}

}  // namespace palpate::server
