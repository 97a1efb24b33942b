// End-to-end tests of who may do what on palpate-server (docs/protocol.md, "Security
// model") and of its limits: the real server process on loopback ports, attacked by real
// Cap'n Proto clients (clients/connect.h, plain TCP or TLS). Each test starts the server
// with the options it needs.
#include <pthread.h>
#include <sched.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <capnp/rpc-twoparty.h>
#include <gtest/gtest.h>
#include <kj/async-io.h>
#include <kj/compat/tls.h>
#include <kj/timer.h>

#include "cli/child_process.h"
#include "clients/connect.h"
#include "tests/e2e/open_session.h"
#include "protocol/palpate.capnp.h"
#include "tests/e2e/ws_client.h"
#include "tests/test_server.h"

namespace {

using palpate::client::ConnectOptions;
using palpate::client::ServerConnection;
using palpate::cli::run_program;
using palpate::test::ServerProcess;
using palpate::wire::FrameSink;
using palpate::wire::PalpateServer;
using palpate::wire::Session;
using Clock = std::chrono::steady_clock;

constexpr int kDelayMs = 100;  // --wrong-token-delay-ms of these tests' servers

// The small haptic scene as the default (a quick start-up check), a short refusal delay,
// then `more`.
std::vector<std::string> server_args(std::vector<std::string> more = {}) {
  std::vector<std::string> a = {"--scene", PALPATE_SOURCE_DIR "/scenes/hertz_cube_haptic.json",
                                "--wrong-token-delay-ms", std::to_string(kDelayMs)};
  a.insert(a.end(), more.begin(), more.end());
  return a;
}

// A temporary folder, removed at the end.
struct TempDir {
  TempDir() : path(std::filesystem::temp_directory_path() / ("palpate-security-" + std::to_string(getpid()))) {
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(path / name) << text;
    return (path / name).string();
  }
  std::filesystem::path path;
};

// The test thread's one event loop, which every Client of a test shares.
kj::AsyncIoContext& thread_io() {
  static kj::AsyncIoContext io = kj::setupAsyncIo();
  return io;
}

struct Client {
  explicit Client(const ServerProcess& server, ConnectOptions o = {})
      : c(with_address(server, std::move(o)), thread_io()) {}
  ServerConnection c;
  PalpateServer::Client server() { return c.server(); }
  kj::WaitScope& ws() { return c.wait_scope(); }
  void pump(int ms) { c.timer().afterDelay(ms * kj::MILLISECONDS).wait(ws()); }

  // The error message of a failing call, or "" if it succeeded.
  template <class Request>
  std::string error_of(Request&& req) {
    return palpate::test::error_of(std::forward<Request>(req), ws());
  }

 private:
  static ConnectOptions with_address(const ServerProcess& server, ConnectOptions o) {
    o.address = server.address();
    return o;
  }
};

struct Opened {
  Session::Client session;
  uint32_t id;
  std::string token;
};

// hertz_cube at 8 per edge (headless unless asked), as its opener sees it.
Opened open(Client& c, bool headless = true, double rate_hz = 0.0, const std::string& per_edge = "8") {
  auto req = c.server().openSessionRequest();
  auto r = req.initRequest();
  r.getScene().setName("hertz_cube");
  r.initOverrides(1).set(0, "body.distribution.per_edge=" + per_edge);
  r.setHeadless(headless);
  r.setRateHz(rate_hz);
  auto res = req.send().wait(c.ws());
  EXPECT_TRUE(res.getInfo().getControl());
  return {res.getSession(), res.getInfo().getSessionId(), res.getControlToken()};
}

std::string open_error(Client& c) {
  auto req = c.server().openSessionRequest();
  auto r = req.initRequest();
  r.getScene().setName("hertz_cube");
  r.initOverrides(1).set(0, "body.distribution.per_edge=6");
  r.setHeadless(true);
  return c.error_of(req);
}

auto attach_request(Client& c, uint32_t id, const std::string& token) {
  auto req = c.server().attachRequest();
  req.setSessionId(id);
  req.setControlToken(token);
  return req;
}

class CountingSink final : public FrameSink::Server {
 public:
  explicit CountingSink(int& frames, std::string& done) : frames_(frames), done_(done) {}

 protected:
  kj::Promise<void> frame(FrameContext) override {
    ++frames_;
    return kj::READY_NOW;
  }
  kj::Promise<void> done(DoneContext context) override {
    done_ = context.getParams().getReason();
    return kj::READY_NOW;
  }

 private:
  int& frames_;
  std::string& done_;
};

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// ---------------------------------------------------------------------------

TEST(Security, AReadOnlyViewCannotCommandAndChangesNothing) {
  ServerProcess server(server_args());
  Client owner(server);
  Opened s = open(owner);
  EXPECT_EQ(s.token.size(), 64u);
  auto step = s.session.stepRequest();
  step.setN(10);
  step.send().wait(owner.ws());
  const auto before_response = s.session.statusRequest().send().wait(owner.ws());  // owns what the reader reads
  const auto before = before_response.getStatus();
  const int64_t tick = before.getTick();
  const double force = before.getForceCommand();

  Client viewer(server);
  auto attached = attach_request(viewer, s.id, "").send().wait(viewer.ws());
  EXPECT_FALSE(attached.getInfo().getControl());
  EXPECT_EQ(attached.getInfo().getSessionId(), s.id);
  Session::Client view = attached.getSession();

  // Every command is refused, saying why.
  std::vector<std::pair<const char*, std::string>> refused;
  {
    auto r = view.setForceRequest();
    r.setNewtons(5.0);
    refused.emplace_back("setForce", viewer.error_of(r));
  }
  {
    auto r = view.setForceVectorRequest();
    r.initForce().setZ(-5.0);
    refused.emplace_back("setForceVector", viewer.error_of(r));
  }
  {
    auto r = view.setPositionRequest();
    r.initPosition().setZ(0.5);
    refused.emplace_back("setPosition", viewer.error_of(r));
  }
  {
    auto r = view.setCouplingRequest();
    r.initCoupling().setStiffness(100.0);
    refused.emplace_back("setCoupling", viewer.error_of(r));
  }
  refused.emplace_back("reset", viewer.error_of(view.resetRequest()));
  refused.emplace_back("pause", viewer.error_of(view.pauseRequest()));
  refused.emplace_back("resume", viewer.error_of(view.resumeRequest()));
  {
    auto r = view.stepRequest();
    r.setN(5);
    refused.emplace_back("step", viewer.error_of(r));
  }
  refused.emplace_back("close", viewer.error_of(view.closeRequest()));
  for (const auto& [method, error] : refused) {
    EXPECT_NE(error.find(std::string(method) + ": this is a read-only view of session " + std::to_string(s.id)),
              std::string::npos)
        << method << ": " << error;
  }

  // Nothing changed: the owner's session is where it was, open, and still obeys its owner.
  const auto after_response = s.session.statusRequest().send().wait(owner.ws());
  const auto after = after_response.getStatus();
  EXPECT_EQ(after.getTick(), tick);
  EXPECT_EQ(after.getForceCommand(), force);
  EXPECT_FALSE(after.getClosed());

  // What a view may do: info, stats, status, and a subscription that sees the owner's steps.
  EXPECT_FALSE(view.infoRequest().send().wait(viewer.ws()).getInfo().getControl());
  EXPECT_EQ(view.statusRequest().send().wait(viewer.ws()).getStatus().getTick(), tick);
  EXPECT_EQ(view.statsRequest().send().wait(viewer.ws()).getStats().getTicks(), tick);
  int frames = 0;
  std::string done;
  auto sub = view.subscribeRequest();
  sub.setSink(kj::heap<CountingSink>(frames, done));
  auto handle = sub.send().wait(viewer.ws()).getSubscription();
  auto set = s.session.setForceRequest();
  set.setNewtons(3.0);
  set.send().wait(owner.ws());
  auto step_again = s.session.stepRequest();
  step_again.setN(10);
  step_again.send().wait(owner.ws());
  for (int k = 0; k < 100 && frames == 0; ++k) viewer.pump(10);
  EXPECT_GE(frames, 1) << "the view's subscription saw no frame of the owner's step";
  EXPECT_EQ(view.statusRequest().send().wait(viewer.ws()).getStatus().getForceCommand(), 3.0);
}

TEST(Security, OnlyTheSessionsOwnTokenGivesControlAndWrongTokensCostTime) {
  ServerProcess server(server_args());
  Client owner(server);
  Opened a = open(owner), b = open(owner);
  EXPECT_NE(a.token, b.token);
  EXPECT_NE(a.id, b.id);

  Client other(server);
  // Another session's token, and the right token with one digit changed: refused, naming
  // the field, after the delay.
  std::string almost = a.token;
  almost.back() = almost.back() == '0' ? '1' : '0';
  for (const std::string& wrong : {b.token, almost, std::string("00"), a.token + "0"}) {
    const auto t0 = Clock::now();
    const std::string error = other.error_of(attach_request(other, a.id, wrong));
    EXPECT_NE(error.find("attach: controlToken: not the control token of session " + std::to_string(a.id)),
              std::string::npos)
        << error;
    EXPECT_GE(ms_since(t0), 0.9 * kDelayMs) << "a wrong token was answered at once";
  }

  // The right one: a control reference, as good as the owner's.
  auto attached = attach_request(other, a.id, a.token).send().wait(other.ws());
  EXPECT_TRUE(attached.getInfo().getControl());
  auto set = attached.getSession().setForceRequest();
  set.setNewtons(7.0);
  set.send().wait(other.ws());
  auto step = attached.getSession().stepRequest();
  step.setN(2);
  step.send().wait(other.ws());
  EXPECT_EQ(a.session.statusRequest().send().wait(owner.ws()).getStatus().getForceCommand(), 7.0);
  // Session b saw none of it.
  EXPECT_EQ(b.session.statusRequest().send().wait(owner.ws()).getStatus().getForceCommand(), 0.0);
}

TEST(Security, SessionIdsAreRandomAndGuessingStopsAtTheLimit) {
  ServerProcess server(server_args({"--max-wrong-tokens", "5"}));
  Client owner(server);
  std::vector<Opened> sessions;
  for (int k = 0; k < 4; ++k) sessions.push_back(open(owner));
  std::set<uint32_t> ids;
  for (const auto& s : sessions) ids.insert(s.id);
  EXPECT_EQ(ids.size(), 4u);
  // Not a sequence: no id is another's neighbour, and none is a small number.
  for (uint32_t id : ids) {
    EXPECT_EQ(ids.count(id + 1), 0u) << "ids " << id << " and " << id + 1;
    EXPECT_GT(id, 1000u) << "a small id: sequential numbering?";
  }

  // A stranger scanning ids: every guess refused (and answered late), then no more tries.
  Client guesser(server);
  const uint32_t guesses[] = {1, 2, 3, sessions[0].id + 1, sessions[1].id - 1};
  for (uint32_t id : guesses) {
    const std::string error = guesser.error_of(attach_request(guesser, id, ""));
    EXPECT_NE(error.find("attach: sessionId: no live session " + std::to_string(id)), std::string::npos) << error;
  }
  // Five refused: even a right id is refused outright now, at once, naming the limit.
  const auto t0 = Clock::now();
  const std::string limited = guesser.error_of(attach_request(guesser, sessions[0].id, ""));
  EXPECT_NE(limited.find("--max-wrong-tokens 5"), std::string::npos) << limited;
  EXPECT_LT(ms_since(t0), 0.9 * kDelayMs * 5);
  // The connection still answers what needs no guess; another connection may view.
  EXPECT_GT(guesser.server().listScenesRequest().send().wait(guesser.ws()).getNames().size(), 0u);
  Client viewer(server);
  EXPECT_FALSE(attach_request(viewer, sessions[0].id, "").send().wait(viewer.ws()).getInfo().getControl());
}

TEST(Security, AViewDoesNotKeepASessionAliveAfterItsOwnerLeaves) {
  ServerProcess server(server_args());
  Client viewer(server);
  int frames = 0;
  std::string done;
  Session::Client view = nullptr;
  // The viewer's subscription outlives the owner. Releasing it unsubscribes, with no done()
  // (docs/protocol.md: "Releasing the returned Subscription ... unsubscribes"), so a release
  // that reached the server before the owner's disconnection left no subscriber to tell
  // (seen under load: done stayed empty).
  palpate::wire::Subscription::Client handle = nullptr;
  {
    Client owner(server);
    Opened s = open(owner, /*headless=*/false);
    view = attach_request(viewer, s.id, "").send().wait(viewer.ws()).getSession();
    auto sub = view.subscribeRequest();
    sub.setSink(kj::heap<CountingSink>(frames, done));
    sub.getOptions().setRateHz(100);
    handle = sub.send().wait(viewer.ws()).getSubscription();
    for (int k = 0; k < 200 && frames < 3; ++k) viewer.pump(10);
    EXPECT_GE(frames, 3);
    // The owner's connection ends here.
  }
  for (int k = 0; k < 300 && done.empty(); ++k) viewer.pump(10);
  EXPECT_EQ(done, "session closed");
  std::string error;
  try {
    view.statusRequest().send().wait(viewer.ws());
  } catch (const kj::Exception& e) {
    error = e.getDescription().cStr();
  }
  EXPECT_NE(error.find("has ended (its owner closed it or left)"), std::string::npos) << error;
}

TEST(Security, LimitsAreEnforcedWithMessagesThatNameThem) {
  ServerProcess server(server_args({"--max-sessions", "3", "--max-sessions-per-connection", "2",
                                    "--max-subscribers", "2", "--max-message-bytes", "65536"}));
  Client first(server), second(server);
  Opened a = open(first), b = open(first);
  std::string error = open_error(first);
  EXPECT_NE(error.find("this connection already has 2 live sessions"), std::string::npos) << error;
  EXPECT_NE(error.find("--max-sessions-per-connection 2"), std::string::npos) << error;
  Opened c = open(second);
  error = open_error(second);
  EXPECT_NE(error.find("the server already runs 3 sessions"), std::string::npos) << error;
  EXPECT_NE(error.find("--max-sessions 3"), std::string::npos) << error;
  // A closed session gives its slot back at once.
  b.session.closeRequest().send().wait(first.ws());
  Opened d = open(first);

  // Subscribers per session: views count too.
  int frames = 0;
  std::string done;
  std::vector<capnp::Capability::Client> handles;
  for (int k = 0; k < 2; ++k) {
    auto sub = a.session.subscribeRequest();
    sub.setSink(kj::heap<CountingSink>(frames, done));
    handles.push_back(sub.send().wait(first.ws()).getSubscription());
  }
  auto view = attach_request(second, a.id, "").send().wait(second.ws()).getSession();
  auto third = view.subscribeRequest();
  third.setSink(kj::heap<CountingSink>(frames, done));
  error = second.error_of(third);
  EXPECT_NE(error.find("already has 2 subscribers"), std::string::npos) << error;
  EXPECT_NE(error.find("--max-subscribers 2"), std::string::npos) << error;

  // A message over --max-message-bytes ends its own connection, nobody else's.
  {
    Client big(server);
    auto req = big.server().openSessionRequest();
    auto r = req.initRequest();
    r.getScene().setName("hertz_cube");
    r.initOverrides(1).set(0, "name=" + std::string(100000, 'x'));
    r.setHeadless(true);
    error = big.error_of(req);
    EXPECT_FALSE(error.empty()) << "a 100 kB message was accepted under a 64 kB limit";
    EXPECT_EQ(big.error_of(big.server().versionRequest()).empty(), false) << "its connection went on";
  }
  EXPECT_TRUE(server.alive());
  auto step = a.session.stepRequest();
  step.setN(1);
  EXPECT_EQ(first.error_of(step), "");
  (void)c;
  (void)d;
}

TEST(Security, TheAccessTokenGatesEveryConnection) {
  TempDir dir;
  const std::string token = "5f1c0e2a9b7d4c3e8a6f0b1d2c3e4f5a6b7c8d9e0f1a2b3c4d5e6f708192a3b4";
  const std::string file = dir.write("token", token + "\n");
  ServerProcess server(server_args({"--access-token-file", file, "--http", "127.0.0.1:0"}));

  Client anonymous(server);
  // version() is answered, so that a client can tell what it talks to; nothing else is.
  EXPECT_EQ(anonymous.server().versionRequest().send().wait(anonymous.ws()).getProtocolVersion(),
            palpate::wire::PROTOCOL_VERSION);
  for (const std::string& error :
       {open_error(anonymous), anonymous.error_of(anonymous.server().listScenesRequest()),
        anonymous.error_of(attach_request(anonymous, 1, ""))})
    EXPECT_NE(error.find("this server requires an access token"), std::string::npos) << error;
  auto wrong = anonymous.server().authenticateRequest();
  wrong.setAccessToken(token.substr(0, 63) + "0");
  const auto t0 = Clock::now();
  const std::string error = anonymous.error_of(wrong);
  EXPECT_NE(error.find("authenticate: accessToken: not this server's access token"), std::string::npos) << error;
  EXPECT_GE(ms_since(t0), 0.9 * kDelayMs);

  // The right token (clients/connect.h presents it): the whole protocol.
  ConnectOptions with_token;
  with_token.access_token = token;
  Client member(server, with_token);
  Opened s = open(member);
  auto step = s.session.stepRequest();
  step.setN(3);
  EXPECT_EQ(step.send().wait(member.ws()).getFrame().getTick(), 3);

  // The WebSocket listener asks for the same token.
  {
    palpate::test::WsRpcConnection ws(thread_io(), server.web_port());
    ASSERT_EQ(ws.status, 101u);
    auto scenes = ws.server.listScenesRequest();
    std::string refused;
    try {
      scenes.send().wait(thread_io().waitScope);
    } catch (const kj::Exception& e) {
      refused = e.getDescription().cStr();
    }
    EXPECT_NE(refused.find("this server requires an access token"), std::string::npos) << refused;
    auto auth = ws.server.authenticateRequest();
    auth.setAccessToken(token);
    auto member_ws = auth.send().wait(thread_io().waitScope).getServer();
    EXPECT_GT(member_ws.listScenesRequest().send().wait(thread_io().waitScope).getNames().size(), 0u);
  }

  // palpate-client with --access-token-file, and without it.
  const auto with = run_program({PALPATE_CLIENT_BIN, "--connect", server.address(), "--access-token-file", file,
                                 "--headless", "--scene", "hertz_cube", "--set", "body.distribution.per_edge=6",
                                 "--forces", "0.05", "--max-steps", "200"},
                                std::chrono::seconds(60));
  EXPECT_EQ(with.status, 0) << with.err;
  const auto without = run_program({PALPATE_CLIENT_BIN, "--connect", server.address(), "--headless"},
                                   std::chrono::seconds(60));
  EXPECT_EQ(without.status, 1);
  EXPECT_NE(without.err.find("requires an access token"), std::string::npos) << without.err;
}

TEST(Security, SecretsThatCannotBeUsedStopTheServerNamingTheFile) {
  TempDir dir;
  const std::string short_token = dir.write("short", "0123456789abcdef\n");
  const std::string spaced = dir.write("spaced", "0123456789abcdef 0123456789abcdef0123\n");
  const std::string not_pem = dir.write("cert.pem", "not a certificate\n");
  struct Case {
    std::vector<std::string> args;
    std::string expect;
  };
  const std::vector<Case> cases = {
      {{"--access-token-file", short_token}, short_token + ": the access token has 16 characters, fewer than 32"},
      {{"--access-token-file", spaced}, spaced + ": the access token holds white space"},
      {{"--access-token-file", (dir.path / "missing").string()}, (dir.path / "missing").string() + ": cannot be read"},
      {{"--tls-cert", not_pem}, "--tls-cert and --tls-key go together"},
      {{"--tls-cert", not_pem, "--tls-key", not_pem}, "not a PEM certificate and private key"},
      {{"--tls-cert", (dir.path / "none.pem").string(), "--tls-key", not_pem}, "none.pem: cannot be read"},
  };
  for (const auto& c : cases) {
    std::vector<std::string> argv = {PALPATE_SERVER_BIN, "--listen", "127.0.0.1:0"};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    const auto r = run_program(argv, std::chrono::seconds(30));
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_NE(r.err.find(c.expect), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find("listening"), std::string::npos) << "it listened: " << r.out;
  }
}

// A self-signed certificate for localhost and 127.0.0.1 (openssl, scripts/setup.sh).
struct Certificate {
  Certificate(const TempDir& dir, const std::string& name) {
    cert = (dir.path / (name + ".pem")).string();
    key = (dir.path / (name + ".key")).string();
    const auto r = run_program({"/usr/bin/openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                                "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", key, "-out", cert, "-days", "2",
                                "-subj", "/CN=localhost", "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1"},
                               std::chrono::seconds(30));
    EXPECT_EQ(r.status, 0) << r.err;
  }
  std::string cert, key;
};

// One HTTP/1.1 GET over TLS to 127.0.0.1:port trusting `ca`: the whole response.
std::string https_get(int port, const std::string& ca_file, const std::string& path) {
  auto& io = thread_io();
  std::ifstream in(ca_file);
  const std::string pem((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  kj::TlsCertificate ca(kj::StringPtr(pem.c_str()));
  kj::TlsContext::Options o;
  o.trustedCertificates = kj::arrayPtr(&ca, 1);
  o.useSystemTrustStore = false;
  kj::TlsContext tls(kj::mv(o));
  auto address = io.provider->getNetwork().parseAddress("127.0.0.1", port).wait(io.waitScope);
  auto stream = tls.wrapClient(address->connect().wait(io.waitScope), "localhost").wait(io.waitScope);
  const std::string request = "GET " + path + " HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n";
  stream->write(request.data(), request.size()).wait(io.waitScope);
  std::string response;
  char buf[4096];
  for (;;) {
    const size_t n = stream->tryRead(buf, 1, sizeof buf).wait(io.waitScope);
    if (n == 0) break;
    response.append(buf, n);
    if (response.find("\r\n\r\n") != std::string::npos && response.size() > 200) break;
  }
  return response;
}

TEST(Security, TlsOnBothListeners) {
  TempDir dir;
  Certificate server_cert(dir, "server"), other(dir, "other");
  ServerProcess server(server_args({"--tls-cert", server_cert.cert, "--tls-key", server_cert.key, "--http",
                                    "127.0.0.1:0"}));

  // A client that trusts the server's certificate: the whole protocol over TLS.
  ConnectOptions trusting;
  trusting.tls_ca_file = server_cert.cert;
  trusting.tls_server_name = "localhost";
  Client client(server, trusting);
  Opened s = open(client);
  auto step = s.session.stepRequest();
  step.setN(4);
  EXPECT_EQ(step.send().wait(client.ws()).getFrame().getTick(), 4);

  // One that trusts another certificate: the handshake fails, nothing is served.
  ConnectOptions distrusting;
  distrusting.tls_ca_file = other.cert;
  distrusting.tls_server_name = "localhost";
  EXPECT_ANY_THROW(Client refused(server, distrusting));

  // A plain client gets no answer from the TLS port (the handshake fails or times out).
  {
    auto& io = thread_io();
    auto stream = io.provider->getNetwork().parseAddress(server.address()).wait(io.waitScope)->connect().wait(io.waitScope);
    capnp::TwoPartyClient plain(*stream);
    auto version = plain.bootstrap().castAs<PalpateServer>().versionRequest().send();
    auto timeout = io.provider->getTimer().afterDelay(3 * kj::SECONDS).then([]() -> bool { return false; });
    bool answered = false;
    try {
      answered = version.then([](auto&&) { return true; }).exclusiveJoin(kj::mv(timeout)).wait(io.waitScope);
    } catch (const kj::Exception&) {
      answered = false;
    }
    EXPECT_FALSE(answered) << "a plain-TCP client was answered by the TLS listener";
  }

  // The web listener over TLS: /healthz.
  const std::string health = https_get(server.web_port(), server_cert.cert, "/healthz");
  EXPECT_NE(health.find("HTTP/1.1 200"), std::string::npos) << health;
  EXPECT_TRUE(server.alive());
}

// Overload (issue: "overload never starves control"): real-time sessions that need more
// than both cores at SCHED_FIFO, and the server must still answer stats(), /healthz and
// close() promptly, because its loops give way to a starved RPC thread
// (Deadlines::give_way_to). The client's own thread runs above the loops' priority, so that
// what is measured is the server's answer, not the client's wait for a core. Wall-clock:
// ctest entry server_security_timing, label `timing`; not run in the sanitized builds
// (tests/CMakeLists.txt).
TEST(SecurityTiming, OverloadNeverStarvesControl) {
  sched_param param{};
  param.sched_priority = 20;
  if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &param) != 0)
    GTEST_SKIP() << "SCHED_FIFO refused here: the loops would not starve anything either";
  struct Restore {
    ~Restore() {
      sched_param p{};
      pthread_setschedparam(pthread_self(), SCHED_OTHER, &p);
    }
  } restore;
  ServerProcess server(server_args({"--http", "127.0.0.1:0", "--max-sessions-per-connection", "8"}));
  Client c(server);
  // Each 18^3 cube at 2 kHz needs about a core (a step of ~0.4 ms); six need three.
  std::vector<Opened> sessions;
  for (int k = 0; k < 6; ++k) sessions.push_back(open(c, /*headless=*/false, 2000.0, "18"));
  c.pump(1000);
  const auto stats0 = sessions[0].session.statsRequest().send().wait(c.ws());
  if (!stats0.getStats().getRealtimePriority()) GTEST_SKIP() << "the loops were not granted SCHED_FIFO";

  std::vector<double> stats_ms, health_ms, close_ms;
  for (int k = 0; k < 20; ++k) {
    const auto t0 = Clock::now();
    sessions[k % sessions.size()].session.statsRequest().send().wait(c.ws());
    stats_ms.push_back(ms_since(t0));
    c.pump(20);
  }
  // /healthz over plain HTTP on the web port (a kj client on this thread).
  for (int k = 0; k < 10; ++k) {
    const auto t0 = Clock::now();
    auto address = c.c.io_provider().getNetwork().parseAddress("127.0.0.1", server.web_port()).wait(c.ws());
    auto stream = address->connect().wait(c.ws());
    const std::string request = "GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
    stream->write(request.data(), request.size()).wait(c.ws());
    char buf[512];
    const size_t n = stream->tryRead(buf, 12, sizeof buf).wait(c.ws());
    health_ms.push_back(ms_since(t0));
    EXPECT_GE(n, 12u);
    c.pump(20);
  }
  uint64_t misses = 0, yields = 0;
  for (auto& s : sessions) {
    const auto response = s.session.statsRequest().send().wait(c.ws());
    misses += response.getStats().getDeadlineMisses();
    yields += response.getStats().getWatchdogYields();
  }
  for (auto& s : sessions) {
    const auto t0 = Clock::now();
    s.session.closeRequest().send().wait(c.ws());
    close_ms.push_back(ms_since(t0));
  }
  auto summary = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return std::make_pair(v[v.size() / 2], v.back());
  };
  const auto [stats_p50, stats_max] = summary(stats_ms);
  const auto [health_p50, health_max] = summary(health_ms);
  const auto [close_p50, close_max] = summary(close_ms);
  std::printf("overload (6 x 18^3 cube at 2 kHz, SCHED_FIFO): %llu misses, %llu watchdog rests; stats() p50 %.1f max "
              "%.1f ms, /healthz p50 %.1f max %.1f ms, close() p50 %.1f max %.1f ms\n",
              static_cast<unsigned long long>(misses), static_cast<unsigned long long>(yields), stats_p50, stats_max,
              health_p50, health_max, close_p50, close_max);
  EXPECT_GT(misses, 0u) << "the sessions were not overloaded: the test proves nothing";
  // The bound: 50 ms at the median, and no answer later than 250 ms (a shared VM's hiccups).
  EXPECT_LE(stats_p50, 50.0);
  EXPECT_LE(health_p50, 50.0);
  EXPECT_LE(close_p50, 50.0);
  EXPECT_LE(std::max({stats_max, health_max, close_max}), 250.0);
}

}  // namespace
