// End-to-end test of palpate-server --agones (server/agones.h) against a stand-in for the
// Agones SDK sidecar: a kj-http server in this process on 127.0.0.1 that answers every
// request 200 "{}" and records its method, path, body, Content-Type and arrival time —
// the sidecar's REST contract (POST /ready, /health, /shutdown with a JSON body), not a
// copy of Agones. The calls are printed for the record.
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <capnp/ez-rpc.h>
#include <gtest/gtest.h>
#include <kj/async-io.h>
#include <kj/compat/http.h>

#include "cli/child_process.h"
#include "protocol/palpate.capnp.h"
#include "tests/e2e/open_session.h"
#include "tests/test_server.h"

namespace {

using Clock = std::chrono::steady_clock;
using palpate::test::open_session;
using palpate::test::ServerProcess;
using palpate::wire::FrameSink;
using palpate::wire::PalpateServer;

struct SidecarCall {
  std::string method, path, body, content_type;
  Clock::time_point at;
};

// The stand-in sidecar: its own thread and event loop (the test's thread runs the
// Cap'n Proto client's), listening on 127.0.0.1:port (0: the system picks).
class FakeSidecar {
 public:
  explicit FakeSidecar(unsigned port = 0) : thread_([this, port] { run(port); }) {
    std::unique_lock<std::mutex> lock(m_);
    cv_.wait(lock, [&] { return listening_ || failed_; });
    if (failed_) {
      std::fprintf(stderr, "the fake sidecar cannot listen on 127.0.0.1:%u\n", port);
      std::abort();
    }
  }
  ~FakeSidecar() {
    {
      std::lock_guard<std::mutex> lock(m_);
      stop_->fulfill();
    }
    thread_.join();
  }
  unsigned port() const {
    std::lock_guard<std::mutex> lock(m_);
    return port_;
  }
  std::vector<SidecarCall> calls() const {
    std::lock_guard<std::mutex> lock(m_);
    return calls_;
  }

 private:
  class Service final : public kj::HttpService {
   public:
    Service(FakeSidecar& owner, const kj::HttpHeaderTable& table) : owner_(owner), table_(table) {}
    kj::Promise<void> request(kj::HttpMethod method, kj::StringPtr url, const kj::HttpHeaders& headers,
                              kj::AsyncInputStream& body, Response& response) override {
      const Clock::time_point at = Clock::now();
      SidecarCall call{kj::str(method).cStr(), url.cStr(), "", "", at};
      KJ_IF_MAYBE (type, headers.get(kj::HttpHeaderId::CONTENT_TYPE)) call.content_type = type->cStr();
      return body.readAllText().then([this, call = std::move(call), &response](kj::String text) mutable {
        call.body = text.cStr();
        {
          std::lock_guard<std::mutex> lock(owner_.m_);
          owner_.calls_.push_back(std::move(call));
        }
        kj::HttpHeaders reply(table_);
        reply.set(kj::HttpHeaderId::CONTENT_TYPE, "application/json");
        auto out = response.send(200, "OK", reply, uint64_t{2});
        auto written = out->write("{}", 2);
        return written.attach(kj::mv(out));
      });
    }

   private:
    FakeSidecar& owner_;
    const kj::HttpHeaderTable& table_;
  };

  void run(unsigned port) {
    auto io = kj::setupAsyncIo();
    kj::HttpHeaderTable table;
    Service service(*this, table);
    kj::HttpServer http(io.provider->getTimer(), table, service);
    kj::Own<kj::ConnectionReceiver> listener;
    try {
      listener = io.provider->getNetwork().parseAddress("127.0.0.1", port).wait(io.waitScope)->listen();
    } catch (const kj::Exception&) {
      std::lock_guard<std::mutex> lock(m_);
      failed_ = true;
      cv_.notify_all();
      return;
    }
    auto stop = kj::newPromiseAndCrossThreadFulfiller<void>();
    {
      std::lock_guard<std::mutex> lock(m_);
      port_ = listener->getPort();
      stop_ = kj::mv(stop.fulfiller);
      listening_ = true;
    }
    cv_.notify_all();
    http.listenHttp(*listener).exclusiveJoin(kj::mv(stop.promise)).wait(io.waitScope);
  }

  mutable std::mutex m_;
  std::condition_variable cv_;
  std::vector<SidecarCall> calls_;
  unsigned port_ = 0;
  bool listening_ = false, failed_ = false;
  kj::Own<kj::CrossThreadPromiseFulfiller<void>> stop_;
  std::thread thread_;  // last: started once the members above exist
};

// A loopback port nobody listens on (bound, read, released).
unsigned free_port() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof addr;
  if (bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &length) != 0)
    std::abort();
  close(fd);
  return ntohs(addr.sin_port);
}

// The status code of GET /healthz on the web port ("" when there is no answer).
std::string healthz_status(int port) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string reply;
  if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) {
    const std::string request = "GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n";
    if (send(fd, request.data(), request.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(request.size())) {
      char buf[512];
      ssize_t n = 0;
      while (reply.size() < 12 && (n = recv(fd, buf, sizeof buf, 0)) > 0) reply.append(buf, static_cast<size_t>(n));
    }
  }
  close(fd);
  return reply.size() >= 12 ? reply.substr(9, 3) : "";  // "HTTP/1.1 503 ..."
}

class DoneSink final : public FrameSink::Server {
 public:
  size_t frames = 0;
  bool finished = false;
  Clock::time_point finished_at;

 protected:
  kj::Promise<void> frame(FrameContext) override {
    ++frames;
    return kj::READY_NOW;
  }
  kj::Promise<void> done(DoneContext) override {
    finished = true;
    finished_at = Clock::now();
    return kj::READY_NOW;
  }
};

double ms_between(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double, std::milli>(to - from).count();
}

// /health calls that arrived in [from, to].
int pings_between(const std::vector<SidecarCall>& calls, Clock::time_point from, Clock::time_point to) {
  int n = 0;
  for (const SidecarCall& c : calls) n += c.path == "/health" && c.at >= from && c.at <= to;
  return n;
}

constexpr double kPeriodS = 0.2;  // --agones-health-seconds

// Timing (ctest entry agones_e2e_timing, label `timing`): every judgement here is made over
// windows of wall time (pings per period, a session holding its rate or not).
TEST(AgonesE2ETiming, ReadyRetriedThenHealthWhileTheRateHoldsAndShutdownAfterTheSessions) {
  using namespace std::chrono_literals;
  // The server first, the sidecar a second later: /ready must be retried until it listens.
  const unsigned port = free_port();
  ServerProcess server({"--agones", "--agones-port", std::to_string(port), "--agones-health-seconds",
                        std::to_string(kPeriodS), "--http", "127.0.0.1:0", "--no-realtime", "--log-level", "info"});
  const Clock::time_point t0 = server.started();
  std::this_thread::sleep_for(1s);
  FakeSidecar sidecar(port);
  const Clock::time_point sidecar_up = Clock::now();

  capnp::EzRpcClient client(server.address());
  auto& ws = client.getWaitScope();
  auto pump = [&](std::chrono::milliseconds ms) {
    client.getIoProvider().getTimer().afterDelay(ms.count() * kj::MILLISECONDS).wait(ws);
  };
  auto main = client.getMain<PalpateServer>();

  // 1. Ready, then pings at the period (no session: nothing to judge, healthy).
  pump(2500ms);
  auto calls = sidecar.calls();
  ASSERT_FALSE(calls.empty()) << "no call reached the sidecar within 2.5 s of it listening";
  EXPECT_EQ(calls[0].method, "POST");
  EXPECT_EQ(calls[0].path, "/ready") << "the first call";
  EXPECT_EQ(calls[0].body, "{}");
  EXPECT_EQ(calls[0].content_type, "application/json");
  EXPECT_LT(ms_between(sidecar_up, calls[0].at), 2500.0) << "/ready is retried at least every 2 s";
  const Clock::time_point ready_at = calls[0].at;
  {
    const int pings = pings_between(calls, ready_at, ready_at + 2000ms);
    // 10 expected; a loaded machine delays timers (fewer), never more than the grid.
    EXPECT_GE(pings, 6) << "health pings every " << kPeriodS << " s";
    EXPECT_LE(pings, 11);
    for (const SidecarCall& c : calls) {
      if (c.path == "/health") {
        EXPECT_TRUE(c.method == "POST" && c.body == "{}" && c.content_type == "application/json");
      }
    }
  }

  // 2. A session that holds its rate (coarse cube, 100 Hz) keeps the pings going; its
  // subscriber is told when the server shuts down.
  auto light = open_session(main, ws, false, {"body.distribution.per_edge=8"}, 100.0);
  auto sink_owner = kj::heap<DoneSink>();
  DoneSink& sink = *sink_owner;
  FrameSink::Client sink_cap = kj::mv(sink_owner);  // held here: it outlives the server's reference
  auto subscribe = light.subscribeRequest();
  subscribe.setSink(sink_cap);
  subscribe.getOptions().setRateHz(10);
  auto subscription = subscribe.send().wait(ws).getSubscription();
  const Clock::time_point light_open = Clock::now();
  pump(2000ms);
  EXPECT_GE(pings_between(sidecar.calls(), light_open + 500ms, light_open + 2000ms), 4)
      << "a session at its rate stopped the pings";

  // 3. A session that cannot hold its rate (the 5832-particle cube, 0.5 ms per RK4 step,
  // asked for 10 kHz): the pings stop. Meanwhile /healthz is asked every 50 ms: it makes
  // the same judgement over intervals of its own, reports the failure, and its frequent
  // probes do not make the pinger's judgement pass.
  auto heavy = open_session(main, ws, false, {}, 10000.0);
  const Clock::time_point heavy_open = Clock::now();
  std::atomic<bool> stop_probing{false};
  std::atomic<int> healthz_503{0}, healthz_other{0};
  std::thread probing([&] {
    while (!stop_probing) {
      const std::string status = healthz_status(server.web_port());
      ++(status == "503" ? healthz_503 : healthz_other);
      std::this_thread::sleep_for(50ms);
    }
  });
  pump(2500ms);
  stop_probing = true;
  probing.join();
  EXPECT_EQ(pings_between(sidecar.calls(), heavy_open + 600ms, heavy_open + 2500ms), 0)
      << "pings went on while a session missed its rate";
  EXPECT_GT(healthz_503.load(), 10) << "/healthz did not report the session missing its rate (" << healthz_other
                                    << " other answers)";
  const double heavy_rate = heavy.statsRequest().send().wait(ws).getStats().getAchievedRateHz();
  EXPECT_LT(heavy_rate, 9000.0) << "the heavy session held 10 kHz: the test proves nothing";

  // 4. Closed, the heavy session no longer counts: the pings resume.
  heavy.closeRequest().send().wait(ws);
  const Clock::time_point heavy_closed = Clock::now();
  pump(2000ms);
  EXPECT_GE(pings_between(sidecar.calls(), heavy_closed + 600ms, heavy_closed + 2000ms), 3)
      << "pings did not resume once every session held its rate";

  // 5. SIGTERM: the sessions are closed (the subscriber gets done), then /shutdown, exit 0.
  const Clock::time_point sigterm_at = Clock::now();
  kill(server.pid(), SIGTERM);
  for (int k = 0; k < 150 && !sink.finished; ++k) pump(20ms);
  EXPECT_TRUE(sink.finished) << "no FrameSink.done before the server exited";
  EXPECT_EQ(server.terminate(std::chrono::seconds(10)), 0) << "no clean exit on SIGTERM";
  calls = sidecar.calls();
  ASSERT_FALSE(calls.empty());
  EXPECT_EQ(calls.back().path, "/shutdown") << "the last call";
  int shutdowns = 0, readies = 0;
  Clock::time_point first_shutdown = calls.back().at;
  for (const SidecarCall& c : calls) {
    if (c.path == "/shutdown" && shutdowns++ == 0) first_shutdown = c.at;
    readies += c.path == "/ready";
  }
  EXPECT_EQ(shutdowns, 1);
  EXPECT_EQ(readies, 1) << "/ready once it was taken";
  if (sink.finished) {
    EXPECT_GT(first_shutdown, sink.finished_at) << "/shutdown before the sessions were closed";
  }
  EXPECT_EQ(calls.back().body, "{}");

  // For the record: every call, its time from the server's listening line.
  std::printf("Agones SDK calls (t from the server's listening line; sidecar up at %.0f ms, light session %.0f ms, "
              "heavy session %.0f ms (%.0f Hz of 10000 achieved), heavy closed %.0f ms, SIGTERM %.0f ms, done() "
              "received %.0f ms):\n",
              ms_between(t0, sidecar_up), ms_between(t0, light_open), ms_between(t0, heavy_open), heavy_rate,
              ms_between(t0, heavy_closed), ms_between(t0, sigterm_at),
              sink.finished ? ms_between(t0, sink.finished_at) : -1.0);
  for (const SidecarCall& c : calls)
    std::printf("  %s %-10s t = %7.1f ms  body %s  Content-Type %s\n", c.method.c_str(), c.path.c_str(),
                ms_between(t0, c.at), c.body.c_str(), c.content_type.c_str());
}

TEST(AgonesE2E, ABadSidecarPortInTheEnvironmentIsRefused) {
  setenv("AGONES_SDK_HTTP_PORT", "http", 1);
  const auto r = palpate::cli::run_program({PALPATE_SERVER_BIN, "--agones", "--listen", "127.0.0.1:0"},
                                            std::chrono::seconds(30));
  unsetenv("AGONES_SDK_HTTP_PORT");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("AGONES_SDK_HTTP_PORT: 'http' is not a port number"), std::string::npos) << r.err;
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
