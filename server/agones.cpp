#include "server/agones.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

#include <kj/debug.h>
#include <spdlog/spdlog.h>

namespace palpate::server {

namespace {

kj::Duration seconds(double s) { return static_cast<int64_t>(std::llround(s * 1e9)) * kj::NANOSECONDS; }

}  // namespace

unsigned agones_port_from_environment() {
  const char* value = std::getenv("AGONES_SDK_HTTP_PORT");
  if (value == nullptr || *value == '\0') return 9358;
  char* end = nullptr;
  const long port = std::strtol(value, &end, 10);
  if (*end != '\0' || port < 1 || port > 65535)
    throw std::invalid_argument(std::string("AGONES_SDK_HTTP_PORT: '") + value +
                                "' is not a port number in [1, 65535]");
  return static_cast<unsigned>(port);
}

AgonesLifecycle::AgonesLifecycle(kj::Timer& timer, kj::Network& network, AgonesOptions options,
                                 std::function<Probe()> healthy)
    : timer_(timer), options_(std::move(options)), healthy_(std::move(healthy)), ready_started_(timer.now()) {
  table_ = kj::heap<kj::HttpHeaderTable>();
  client_ = kj::newHttpClient(timer_, *table_, network, nullptr);
}

AgonesLifecycle::~AgonesLifecycle() = default;

kj::Promise<unsigned> AgonesLifecycle::post(kj::StringPtr path) {
  kj::HttpHeaders headers(*table_);
  headers.set(kj::HttpHeaderId::CONTENT_TYPE, "application/json");
  const auto url = kj::str("http://", options_.host.c_str(), ":", options_.port, path);
  static constexpr char kBody[] = "{}";
  auto request = client_->request(kj::HttpMethod::POST, url, headers, uint64_t{sizeof kBody - 1});
  auto sent = request.body->write(kBody, sizeof kBody - 1).attach(kj::mv(request.body));
  auto answered = sent.then([response = kj::mv(request.response)]() mutable { return kj::mv(response); })
                      .then([](kj::HttpClient::Response&& response) {
                        const unsigned status = response.statusCode;
                        // Read the (small) body to the end so the connection can be reused.
                        return response.body->readAllText().attach(kj::mv(response.body)).then([status](kj::String) {
                          return status;
                        });
                      });
  const double timeout = options_.call_timeout_s;
  return answered.exclusiveJoin(timer_.afterDelay(seconds(timeout)).then([timeout]() -> unsigned {
    KJ_FAIL_REQUIRE("no answer", timeout, "s");
  }));
}

kj::Promise<void> AgonesLifecycle::run() {
  ready_started_ = timer_.now();
  return ready(0.1).then([this]() { return health_loop(timer_.now() + seconds(options_.health_period_s)); });
}

kj::Promise<void> AgonesLifecycle::ready(double backoff_s) {
  auto retry = [this, backoff_s](std::string why) -> kj::Promise<void> {
    const double waited = static_cast<double>((timer_.now() - ready_started_) / kj::MILLISECONDS) * 1e-3;
    spdlog::debug("Agones /ready on {}:{}: {}; again in {:.1f} s", options_.host, options_.port, why, backoff_s);
    if (!warned_ready_ && waited >= kReadyWarnAfter) {
      warned_ready_ = true;
      spdlog::warn("the Agones SDK sidecar at {}:{} has not taken /ready for {:.0f} s ({}); still trying "
                   "(is this pod an Agones GameServer? without Agones, run without --agones)",
                   options_.host, options_.port, waited, why);
    }
    return timer_.afterDelay(seconds(backoff_s)).then([this, backoff_s]() {
      return ready(std::min(2.0 * backoff_s, 2.0));
    });
  };
  return post("/ready").then(
      [this, retry](unsigned status) mutable -> kj::Promise<void> {
        if (status / 100 != 2) return retry("HTTP status " + std::to_string(status));
        if (warned_ready_) spdlog::warn("Agones: Ready after all (sidecar {}:{})", options_.host, options_.port);
        else spdlog::info("Agones: Ready (sidecar {}:{})", options_.host, options_.port);
        return kj::READY_NOW;
      },
      [retry](kj::Exception&& e) mutable { return retry(e.getDescription().cStr()); });
}

kj::Promise<void> AgonesLifecycle::health_loop(kj::TimePoint next) {
  return timer_.atTime(next).then([this, next]() {
    // The next ping on the period's grid, skipping the points already passed.
    const kj::Duration period = seconds(options_.health_period_s);
    kj::TimePoint following = next + period;
    while (following <= timer_.now()) following = following + period;
    const Probe probe = healthy_();
    if (!probe.ok) {
      if (pinging_) spdlog::warn("Agones: health pings stopped: {}", probe.detail);
      pinging_ = false;
      return health_loop(following);
    }
    if (!pinging_) spdlog::warn("Agones: health pings resumed: {}", probe.detail);
    pinging_ = true;
    return post("/health")
        .then(
            [this](unsigned status) {
              if (status / 100 == 2) {
                warned_ping_ = false;
              } else if (!warned_ping_) {
                warned_ping_ = true;
                spdlog::warn("Agones /health: HTTP status {}", status);
              }
            },
            [this](kj::Exception&& e) {
              if (!warned_ping_) {
                warned_ping_ = true;
                spdlog::warn("Agones /health: {}", e.getDescription().cStr());
              }
            })
        .then([this, following]() { return health_loop(following); });
  });
}

kj::Promise<void> AgonesLifecycle::shutdown() {
  return post("/shutdown").then(
      [](unsigned status) {
        if (status / 100 == 2) spdlog::info("Agones: Shutdown");
        else spdlog::warn("Agones /shutdown: HTTP status {}", status);
      },
      [](kj::Exception&& e) { spdlog::warn("Agones /shutdown: {}", e.getDescription().cStr()); });
}

}  // namespace palpate::server
