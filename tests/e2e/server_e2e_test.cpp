// End-to-end tests of palpate-server: the real server process on a loopback port
// (picked by the system: --listen 127.0.0.1:0, the port read from its first
// stdout line), driven by real Cap'n Proto clients.
#include <map>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <set>
#include <algorithm>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <capnp/compat/websocket-rpc.h>
#include <capnp/ez-rpc.h>
#include <capnp/rpc-twoparty.h>
#include <capnp/message.h>
#include <capnp/serialize.h>
#include <gtest/gtest.h>
#include <kj/async-io.h>
#include <kj/compat/http.h>
#include <kj/timer.h>

#include "cli/child_process.h"
#include "protocol/palpate.capnp.h"
#include "tests/e2e/open_session.h"
#include "tests/e2e/ws_client.h"
#include "tests/test_server.h"

namespace {

using palpate::cli::ProgramResult;
using palpate::cli::run_program;

// Wall-clock thresholds. The tests that judge the wall clock (rates, latencies) are in the
// suites ServerE2ETiming and ServerWebSocketTiming: ctest entry server_e2e_timing, label
// `timing` (tests/CMakeLists.txt, docs/robustness.md), which CI runs without failing the
// suite; server_e2e holds the rest, which must pass anywhere. Sanitized builds
// (scripts/test.sh --sanitize) step several times slower and keep freed memory in
// quarantine: there the rates only have to show a live loop, and leaks are
// LeakSanitizer's job, not the RSS check's.
#ifdef PALPATE_SANITIZED
constexpr double kMinRateHz = 200.0;          // real-time loop at 1 kHz, measured rate
constexpr int64_t kMinTicksStepped = 250;     // ticks a full-rate subscriber's frames span over 1.5 s
constexpr int64_t kMaxFrameGapTicks = 200;    // the longest run of ticks without a frame
constexpr long kMaxRssGrowthKb = 1L << 30;    // not checked
#else
constexpr double kMinRateHz = 950.0;
constexpr int64_t kMinTicksStepped = 1000;
constexpr int64_t kMaxFrameGapTicks = 50;
constexpr long kMaxRssGrowthKb = 4096;
#endif

using palpate::wire::FrameSink;
using palpate::wire::PalpateServer;
using palpate::wire::Session;

// ---------------------------------------------------------------------------
// The server process (tests/test_server.h).

using palpate::test::ServerProcess;

ServerProcess* g_server = nullptr;

class ServerEnvironment : public ::testing::Environment {
 public:
  void SetUp() override { g_server = new ServerProcess(); }
  void TearDown() override {
    ASSERT_TRUE(g_server->alive()) << "the server died during the tests";
    EXPECT_EQ(g_server->terminate(std::chrono::seconds(5)), 0) << "no clean exit on SIGTERM";
    delete g_server;
    g_server = nullptr;
  }
};

// A temporary folder of scene files, removed at the end.
struct SceneFolder {
  SceneFolder() : dir("/tmp/palpate-e2e-" + std::to_string(getpid())) { std::filesystem::create_directories(dir); }
  ~SceneFolder() { std::filesystem::remove_all(dir); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(dir + "/" + name) << text;
    return dir + "/" + name;
  }
  std::string dir;
};

// ---------------------------------------------------------------------------
// Client helpers.

struct FrameRecord {
  int64_t tick;
  double contact_force, force_command, indenter_z;
  uint64_t command_seq;
  size_t positions;
  bool finite;
  float largest_coordinate;  // the largest |x| of a streamed position, m
};

class RecordingSink final : public FrameSink::Server {
 public:
  std::vector<FrameRecord> frames;
  bool finished = false;

 protected:
  kj::Promise<void> frame(FrameContext context) override {
    auto f = context.getParams().getFrame();
    FrameRecord r{f.getTick(), f.getIndenterContactForce(), f.getForceCommand(), f.getIndenterPosition().getZ(),
                  f.getCommandSeq(), f.getPositions().size(), true, 0.0f};
    r.finite = std::isfinite(r.contact_force) && std::isfinite(r.indenter_z) && std::isfinite(f.getIndentation()) &&
               std::isfinite(f.getIndenterVelocity());
    for (float x : f.getPositions()) {
      r.finite = r.finite && std::isfinite(x);
      r.largest_coordinate = std::max(r.largest_coordinate, std::abs(x));
    }
    for (float x : f.getContactForces()) r.finite = r.finite && std::isfinite(x);
    frames.push_back(r);
    return kj::READY_NOW;
  }
  kj::Promise<void> done(DoneContext) override {
    finished = true;
    return kj::READY_NOW;
  }
};

// What a full-rate subscriber must have seen over a window, counted in the loop's own
// ticks rather than in wall-clock time: frames spanning the ticks a live loop steps,
// at least one frame for every two ticks, and no long gap. A neighbour that blocked the
// RPC thread or the loop shows as a gap of hundreds of ticks; the RPC thread losing a
// time slice on a loaded two-core machine coalesces a few frames (the newest wins, by
// design) and is not a failure.
void expect_full_rate_delivery(const std::vector<FrameRecord>& frames, const char* who) {
  ASSERT_GE(frames.size(), 2u) << who << ": no stream";
  const int64_t span = frames.back().tick - frames.front().tick + 1;
  int64_t largest_gap = 0;
  for (size_t k = 1; k < frames.size(); ++k) largest_gap = std::max(largest_gap, frames[k].tick - frames[k - 1].tick);
  EXPECT_GE(span, kMinTicksStepped) << who << ": the loop stepped too few ticks";
  EXPECT_GE(static_cast<int64_t>(frames.size()) * 2, span)
      << who << " got " << frames.size() << " frames over " << span << " ticks";
  EXPECT_LE(largest_gap, kMaxFrameGapTicks) << who << " went " << largest_gap << " ticks without a frame";
}

using palpate::test::open_session;

// A client in a thread of its own that opens a real-time session, subscribes to every
// tick's positions and then never reads (its thread stops running its event loop) until
// release() (or 20 s).
template <class ClientType>
class StalledSubscriber {
 public:
  StalledSubscriber() : thread_([this] { run(); }) {
    std::unique_lock<std::mutex> lock(m_);
    cv_.wait_for(lock, std::chrono::seconds(10), [&] { return subscribed_; });
  }
  ~StalledSubscriber() { release(); }
  void release() {
    {
      std::lock_guard<std::mutex> lock(m_);
      release_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

 private:
  void run();
  std::mutex m_;
  std::condition_variable cv_;
  bool subscribed_ = false, release_ = false;
  std::thread thread_;  // last: started once the members above exist
};

struct Client {
  Client() : Client(g_server->address()) {}
  explicit Client(const std::string& address) : ez(address), server(ez.getMain<PalpateServer>()) {}
  capnp::EzRpcClient ez;
  PalpateServer::Client server;
  kj::WaitScope& ws() { return ez.getWaitScope(); }
  void pump(int ms) { ez.getIoProvider().getTimer().afterDelay(ms * kj::MILLISECONDS).wait(ws()); }

  // hertz_cube with overrides ("key=value").
  Session::Client open(bool headless, std::vector<std::string> overrides = {"body.distribution.per_edge=8"}) {
    return open_session(server, ws(), headless, overrides);
  }

  // The hertz_cube of open() with the tool free in 3-D, opened with `device` limits
  // (max stiffness N/m, max damping N s/m, max force N; 0 = none) and a requested coupling.
  Session::Client open_free(bool headless, double max_stiffness = 0, double max_damping = 0, double max_force = 0,
                            double stiffness = 0, double damping = 0) {
    auto req = server.openSessionRequest();
    auto r = req.initRequest();
    r.getScene().setName("hertz_cube");
    auto o = r.initOverrides(2);
    o.set(0, "body.distribution.per_edge=8");
    o.set(1, "indenter.guide=free");
    r.setHeadless(headless);
    auto d = r.initDevice();
    d.setMaxStiffness(max_stiffness);
    d.setMaxDamping(max_damping);
    d.setMaxForce(max_force);
    auto c = r.initCoupling();
    c.setStiffness(stiffness);
    c.setDamping(damping);
    return req.send().wait(ws()).getSession();
  }

  // The error message of a failing call, or "" if it succeeded.
  template <class Request>
  std::string error_of(Request&& req) {
    return palpate::test::error_of(std::forward<Request>(req), ws());
  }
};

std::vector<uint8_t> frame_bytes(palpate::wire::Frame::Reader frame) {
  capnp::MallocMessageBuilder mb;
  mb.setRoot(frame);
  mb.getRoot<palpate::wire::Frame>().setPublishNs(0);  // wall clock: the only non-deterministic field
  auto words = capnp::messageToFlatArray(mb);
  auto bytes = words.asBytes();
  return {bytes.begin(), bytes.end()};
}

template <class ClientType>
void StalledSubscriber<ClientType>::run() {
  ClientType s;
  auto session = open_session(s.server, s.ws(), false);
  auto sub = session.subscribeRequest();
  sub.setSink(kj::heap<RecordingSink>());
  sub.getOptions().setRateHz(0);
  sub.getOptions().getFields().setPositions(true);
  auto handle = sub.send().wait(s.ws()).getSubscription();
  {
    std::lock_guard<std::mutex> lock(m_);
    subscribed_ = true;
  }
  cv_.notify_all();
  std::unique_lock<std::mutex> lock(m_);
  cv_.wait_for(lock, std::chrono::seconds(20), [&] { return release_; });  // never reads meanwhile
}

double achieved_rate(Client& c, Session::Client& s) {
  return s.statsRequest().send().wait(c.ws()).getStats().getAchievedRateHz();
}

// ---------------------------------------------------------------------------

TEST(ServerE2E, VersionAndSessionStreams) {
  Client c;
  auto v = c.server.versionRequest().send().wait(c.ws());
  EXPECT_EQ(v.getProtocolVersion(), palpate::wire::PROTOCOL_VERSION);

  auto session = c.open(false);
  auto sink_owner = kj::heap<RecordingSink>();
  RecordingSink& sink = *sink_owner;
  auto sub = session.subscribeRequest();
  FrameSink::Client sink_cap = kj::mv(sink_owner);  // held here: the sink outlives the server's reference
  sub.setSink(sink_cap);
  sub.getOptions().setRateHz(100);
  sub.getOptions().getFields().setPositions(true);
  auto handle = sub.send().wait(c.ws()).getSubscription();
  c.pump(500);
  ASSERT_GE(sink.frames.size(), 30u);
  EXPECT_LE(sink.frames.size(), 60u);  // rate-limited to 100 Hz
  EXPECT_EQ(sink.frames.back().positions, 3u * 8 * 8 * 8);
  for (size_t k = 1; k < sink.frames.size(); ++k) EXPECT_GT(sink.frames[k].tick, sink.frames[k - 1].tick);

  auto status_response = session.statusRequest().send().wait(c.ws());

  auto status = status_response.getStatus();
  EXPECT_EQ(status.getState(), palpate::wire::RunState::RUNNING);
  // Dropping the handle unsubscribes: no more frames.
  handle = nullptr;
  c.pump(50);
  const size_t count = sink.frames.size();
  c.pump(200);
  EXPECT_EQ(sink.frames.size(), count);
}

// SessionInfo.surfaceTriangles of hertz_cube at 8^3: the box faces, two triangles per face
// cell (6 faces x 7 x 7 cells x 2), valid indices, each edge in two triangles (closed).
TEST(ServerE2E, SessionInfoCarriesTheSurfaceTriangles) {
  Client c;
  auto req = c.server.openSessionRequest();
  auto r = req.initRequest();
  r.getScene().setName("hertz_cube");
  r.initOverrides(1).set(0, "body.distribution.per_edge=8");
  r.setHeadless(true);
  auto response = req.send().wait(c.ws());
  auto info = response.getInfo();
  auto triangles = info.getSurfaceTriangles();
  ASSERT_EQ(triangles.size(), 3u * 6 * 7 * 7 * 2);
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (unsigned k = 0; k < triangles.size(); ++k) {
    ASSERT_LT(triangles[k], info.getParticleCount());
    const unsigned next = k % 3 == 2 ? k - 2 : k + 1;
    ++directed[{triangles[k], triangles[next]}];
  }
  for (const auto& [edge, count] : directed) {
    EXPECT_EQ(count, 1);
    EXPECT_EQ(directed.count({edge.second, edge.first}), 1u);
  }
}

// FrameFields.displacementMagnitude, vonMises and surfaceOnly (docs/protocol.md): sizes, the
// displacement against the positions and restPositions, the surface vertices against the
// triangles, a surface-only twin bit-identical at those vertices, and a real-time subscriber.
TEST(ServerE2E, FramesCarryDisplacementAndVonMisesOnRequest) {
  Client c;
  auto open = [&](bool headless) {
    auto req = c.server.openSessionRequest();
    auto r = req.initRequest();
    r.getScene().setName("hertz_cube");
    r.initOverrides(1).set(0, "body.distribution.per_edge=8");
    r.setHeadless(headless);
    return req.send().wait(c.ws());
  };
  auto full_session = open(true);
  auto twin_session = open(true);
  auto info = full_session.getInfo();
  const unsigned n = info.getParticleCount();
  std::set<uint32_t> referenced;
  for (uint32_t i : info.getSurfaceTriangles()) referenced.insert(i);
  std::vector<uint32_t> vertices;
  for (uint32_t i : info.getSurfaceVertices()) vertices.push_back(i);
  ASSERT_EQ(vertices, std::vector<uint32_t>(referenced.begin(), referenced.end()));  // each once, ascending
  ASSERT_EQ(vertices.size(), 8u * 8 * 8 - 6u * 6 * 6);  // the lattice's boundary nodes

  auto press_and_step = [&](Session::Client session, bool surface_only) {
    auto force = session.setForceRequest();
    force.setNewtons(40.0);
    force.send().wait(c.ws());
    auto step = session.stepRequest();
    step.setN(300);
    auto fields = step.initFields();
    fields.setPositions(true);
    fields.setDisplacementMagnitude(true);
    fields.setVonMises(true);
    fields.setSurfaceOnly(surface_only);
    return step.send().wait(c.ws());
  };
  auto full = press_and_step(full_session.getSession(), false);
  auto twin = press_and_step(twin_session.getSession(), true);
  auto f = full.getFrame();
  auto t = twin.getFrame();
  ASSERT_EQ(f.getPositions().size(), 3 * n);
  ASSERT_EQ(f.getDisplacementMagnitude().size(), n);
  ASSERT_EQ(f.getVonMises().size(), n);
  auto rest = info.getRestPositions();
  float peak = 0;
  for (unsigned i = 0; i < n; ++i) {
    double d2 = 0;
    for (unsigned k = 0; k < 3; ++k) d2 += std::pow(double(f.getPositions()[3 * i + k]) - rest[3 * i + k], 2);
    EXPECT_NEAR(f.getDisplacementMagnitude()[i], std::sqrt(d2), 1e-6) << "particle " << i;
    EXPECT_TRUE(std::isfinite(f.getVonMises()[i]) && f.getVonMises()[i] >= 0) << "particle " << i;
    peak = std::max(peak, f.getVonMises()[i]);
  }
  EXPECT_GT(peak, 10.0f) << "pressed with 40 N: the body is stressed (about 70 Pa at its peak here)";
  ASSERT_EQ(t.getPositions().size(), 3 * vertices.size());
  ASSERT_EQ(t.getVonMises().size(), vertices.size());
  ASSERT_EQ(t.getDisplacementMagnitude().size(), vertices.size());
  EXPECT_EQ(t.getTick(), f.getTick());
  for (size_t p = 0; p < vertices.size(); ++p) {
    const uint32_t i = vertices[p];
    for (unsigned k = 0; k < 3; ++k) EXPECT_EQ(t.getPositions()[3 * p + k], f.getPositions()[3 * i + k]);
    EXPECT_EQ(t.getVonMises()[p], f.getVonMises()[i]);
    EXPECT_EQ(t.getDisplacementMagnitude()[p], f.getDisplacementMagnitude()[i]);
  }
  // Nothing asked, nothing sent.
  auto plain = full_session.getSession().stepRequest();
  plain.setN(1);
  auto plain_response = plain.send().wait(c.ws());
  EXPECT_EQ(plain_response.getFrame().getVonMises().size(), 0u);
  EXPECT_EQ(plain_response.getFrame().getDisplacementMagnitude().size(), 0u);

  // Real time: a subscriber of the surface's von Mises gets it in every frame.
  class VonMisesSink final : public FrameSink::Server {
   public:
    std::vector<size_t> sizes;
    size_t positions = 0;
   protected:
    kj::Promise<void> frame(FrameContext context) override {
      sizes.push_back(context.getParams().getFrame().getVonMises().size());
      positions += context.getParams().getFrame().getPositions().size();
      return kj::READY_NOW;
    }
  };
  auto realtime = c.open(false);
  auto sink_owner = kj::heap<VonMisesSink>();
  VonMisesSink& sink = *sink_owner;
  FrameSink::Client sink_cap = kj::mv(sink_owner);
  auto sub = realtime.subscribeRequest();
  sub.setSink(sink_cap);
  sub.getOptions().setRateHz(50);
  sub.getOptions().getFields().setVonMises(true);
  sub.getOptions().getFields().setSurfaceOnly(true);
  auto handle = sub.send().wait(c.ws()).getSubscription();
  c.pump(400);
  ASSERT_GE(sink.sizes.size(), 5u);
  // The first frame may predate the subscription's request reaching the loop.
  for (size_t k = 2; k < sink.sizes.size(); ++k) EXPECT_EQ(sink.sizes[k], vertices.size()) << "frame " << k;
  EXPECT_EQ(sink.positions, 0u);
}

// Timing: the command crosses the RPC thread and the loop within two 1 ms ticks of wall time.
TEST(ServerE2ETiming, ForceCommandReachesTheStreamWithinTwoTicks) {
  Client c;
  auto session = c.open(false);
  auto sink_owner = kj::heap<RecordingSink>();
  RecordingSink& sink = *sink_owner;
  auto sub = session.subscribeRequest();
  FrameSink::Client sink_cap = kj::mv(sink_owner);  // held here: the sink outlives the server's reference
  sub.setSink(sink_cap);
  sub.getOptions().setRateHz(0);  // every tick
  auto handle = sub.send().wait(c.ws()).getSubscription();
  c.pump(200);

  int observed = 0;
  for (int attempt = 0; attempt < 10 && observed < 3; ++attempt) {
    const double force = attempt % 2 == 0 ? 40.0 : 0.0;
    const size_t before = sink.frames.size();
    const double contact_before = before > 0 ? sink.frames.back().contact_force : 0.0;
    auto req = session.setForceRequest();
    req.setNewtons(force);
    auto res = req.send().wait(c.ws());
    const uint64_t seq = res.getSeq();
    const int64_t queued = res.getQueuedAtTick();
    c.pump(100);
    // The first frame that reflects the command, and the one before it.
    for (size_t k = std::max<size_t>(before, 1); k < sink.frames.size(); ++k) {
      if (sink.frames[k].command_seq < seq) continue;
      const FrameRecord& first = sink.frames[k];
      EXPECT_EQ(first.force_command, force);
      EXPECT_LE(first.tick, queued + 2) << "command applied more than 2 ticks after it was queued";
      if (sink.frames[k - 1].tick == first.tick - 1 && sink.frames[k - 1].command_seq < seq) {
        ++observed;  // gapless: the contact force of the first tick under the new command changed
        EXPECT_GT(std::abs(first.contact_force - contact_before), 1.0)
            << "contact force did not respond in the first tick (" << contact_before << " -> " << first.contact_force
            << ")";
      }
      break;
    }
  }
  EXPECT_GE(observed, 1) << "never saw a gapless command transition";
}

TEST(ServerE2E, PauseResumeAndAttach) {
  Client c;
  auto session = c.open(false);
  const uint32_t id = session.infoRequest().send().wait(c.ws()).getInfo().getSessionId();
  session.pauseRequest().send().wait(c.ws());
  c.pump(50);
  const int64_t t0 = session.statusRequest().send().wait(c.ws()).getStatus().getTick();
  EXPECT_EQ(session.statusRequest().send().wait(c.ws()).getStatus().getState(), palpate::wire::RunState::PAUSED);
  c.pump(100);
  EXPECT_EQ(session.statusRequest().send().wait(c.ws()).getStatus().getTick(), t0);
  session.resumeRequest().send().wait(c.ws());
  // Ticking again: 50 ticks within 5 s of wall time (50 ms in Release; a sanitized
  // build steps several times slower, so the test waits rather than assumes the rate).
  int64_t resumed = t0;
  for (int k = 0; k < 250 && resumed <= t0 + 50; ++k) {
    c.pump(20);
    resumed = session.statusRequest().send().wait(c.ws()).getStatus().getTick();
  }
  EXPECT_GT(resumed, t0 + 50);

  // A second connection attaches to the same session by id.
  Client viewer;
  auto att = viewer.server.attachRequest();
  att.setSessionId(id);
  auto same = att.send().wait(viewer.ws()).getSession();
  auto set = session.setForceRequest();
  set.setNewtons(12.5);
  set.send().wait(c.ws());
  c.pump(20);
  EXPECT_EQ(same.statusRequest().send().wait(viewer.ws()).getStatus().getForceCommand(), 12.5);
  auto bad = viewer.server.attachRequest();
  bad.setSessionId(999999);
  EXPECT_NE(viewer.error_of(bad).find("sessionId"), std::string::npos);
}

TEST(ServerE2E, HeadlessIsDeterministic) {
  Client c;
  auto run_script = [&]() {
    auto session = c.open(true);
    std::vector<std::vector<uint8_t>> frames;
    for (double force : {30.0, 60.0, 10.0}) {
      auto f = session.setForceRequest();
      f.setNewtons(force);
      f.send().wait(c.ws());
      auto step = session.stepRequest();
      step.setN(150);
      step.getFields().setPositions(true);
      step.getFields().setContacts(true);
      auto resp = step.send().wait(c.ws());
      EXPECT_EQ(resp.getFrame().getPositions().size(), 3u * 512);
      frames.push_back(frame_bytes(resp.getFrame()));
    }
    auto r = session.resetRequest().send().wait(c.ws());
    (void)r;
    auto step = session.stepRequest();
    step.setN(10);
    auto resp = step.send().wait(c.ws());
    EXPECT_EQ(resp.getFrame().getTick(), 10);  // reset brought the tick back to 0
    frames.push_back(frame_bytes(resp.getFrame()));
    return frames;
  };
  const auto a = run_script();
  const auto b = run_script();
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k) EXPECT_TRUE(a[k] == b[k]) << "frame " << k << " differs";
}

TEST(ServerE2E, BadScenesAreRefusedNamingTheField) {
  Client c;
  {  // unknown scene name
    auto req = c.server.openSessionRequest();
    req.initRequest().getScene().setName("no_such_scene");
    const std::string e = c.error_of(req);
    EXPECT_NE(e.find("unknown scene 'no_such_scene'"), std::string::npos) << e;
    EXPECT_NE(e.find("hertz_cube"), std::string::npos) << e;  // lists the known ones
  }
  {  // a path instead of a name
    auto req = c.server.openSessionRequest();
    req.initRequest().getScene().setName("../etc/passwd");
    EXPECT_NE(c.error_of(req).find("not a plain scene name"), std::string::npos);
  }
  {  // malformed inline scene: out-of-range Poisson ratio
    auto req = c.server.openSessionRequest();
    auto scene = req.initRequest().getScene().initInlineScene();
    scene.initMaterial().setPoissonRatio(0.7);
    const std::string e = c.error_of(req);
    EXPECT_NE(e.find("/material/poisson_ratio"), std::string::npos) << e;
    EXPECT_NE(e.find("0.7"), std::string::npos) << e;
  }
  {  // malformed inline scene: a vector of two components, NaN in a float
    auto req = c.server.openSessionRequest();
    auto scene = req.initRequest().getScene().initInlineScene();
    auto g = scene.initGravity(2);
    g.set(0, 0);
    g.set(1, 0);
    std::string e = c.error_of(req);
    EXPECT_NE(e.find("/gravity"), std::string::npos) << e;

    auto req2 = c.server.openSessionRequest();
    req2.initRequest().getScene().initInlineScene().initIntegrator().setDt(std::nan(""));
    e = c.error_of(req2);
    EXPECT_NE(e.find("/integrator/dt"), std::string::npos) << e;
  }
  {  // out-of-range parameter through an override, and a bad model name
    auto req = c.server.openSessionRequest();
    auto r = req.initRequest();
    r.getScene().setName("hertz_cube");
    r.initOverrides(1).set(0, "mls.neighbors=2");
    const std::string e = c.error_of(req);
    EXPECT_NE(e.find("/mls/neighbors"), std::string::npos) << e;

    auto req2 = c.server.openSessionRequest();
    req2.initRequest().getScene().initInlineScene().setModel("fem9000");
    EXPECT_NE(c.error_of(req2).find("/model"), std::string::npos);

    auto req3 = c.server.openSessionRequest();
    req3.initRequest().setRateHz(1e9);
    EXPECT_NE(c.error_of(req3).find("rateHz"), std::string::npos);

    auto req4 = c.server.openSessionRequest();  // 200^3 particles: beyond the server's memory bound
    auto r4 = req4.initRequest();
    r4.getScene().setName("hertz_cube");
    r4.initOverrides(1).set(0, "body.distribution.per_edge=200");
    EXPECT_NE(c.error_of(req4).find("/body/distribution"), std::string::npos);
  }
  {  // a valid inline scene opens
    auto req = c.server.openSessionRequest();
    auto r = req.initRequest();
    auto scene = r.getScene().initInlineScene();
    scene.initBody().initDistribution().setPerEdge(6);
    scene.initMaterial().setYoungModulus(2e4);
    r.setHeadless(true);
    auto info_response = req.send().wait(c.ws());
    auto info = info_response.getInfo();
    EXPECT_EQ(info.getParticleCount(), 216u);
    EXPECT_EQ(info.getYoungModulus(), 2e4);
  }
}

TEST(ServerE2E, AbsurdForcesAreRefusedAndTheStateIsUntouched) {
  Client c;
  auto session = c.open(true);
  auto set = session.setForceRequest();
  set.setNewtons(25.0);
  set.send().wait(c.ws());
  auto step = session.stepRequest();
  step.setN(20);
  const auto before = frame_bytes(step.send().wait(c.ws()).getFrame());
  const double limit = session.infoRequest().send().wait(c.ws()).getInfo().getForceLimit();
  EXPECT_GT(limit, 1000.0);

  for (double bad : std::vector<double>{std::nan(""), HUGE_VAL, -HUGE_VAL, 1e12, -2.0 * limit}) {
    auto req = session.setForceRequest();
    req.setNewtons(bad);
    const std::string e = c.error_of(req);
    EXPECT_NE(e.find("newtons"), std::string::npos) << bad << ": " << e;
  }
  auto status_response = session.statusRequest().send().wait(c.ws());
  auto status = status_response.getStatus();
  EXPECT_EQ(status.getForceCommand(), 25.0);
  // A fresh session given the accepted commands only reaches the same frame.
  auto twin = c.open(true);
  auto set2 = twin.setForceRequest();
  set2.setNewtons(25.0);
  set2.send().wait(c.ws());
  auto step2 = twin.stepRequest();
  step2.setN(20);
  EXPECT_TRUE(frame_bytes(step2.send().wait(c.ws()).getFrame()) == before);
  // Both continue identically (nothing was queued by the refused calls).
  auto s1 = session.stepRequest();
  s1.setN(5);
  auto s2 = twin.stepRequest();
  s2.setN(5);
  EXPECT_TRUE(frame_bytes(s1.send().wait(c.ws()).getFrame()) == frame_bytes(s2.send().wait(c.ws()).getFrame()));
  // Real-time only / headless only calls are refused with a reason.
  EXPECT_NE(c.error_of(session.pauseRequest()).find("headless"), std::string::npos);
  auto zero = session.stepRequest();
  zero.setN(0);
  EXPECT_NE(c.error_of(zero).find("n: must be in"), std::string::npos);
}

TEST(ServerE2E, BlowUpIsDetectedRecoveredAndNeverStreamed) {
  Client c;
  // E = 2e8 Pa at dt = 1 ms is 1.2x beyond RK4's stability limit for this cloud (the
  // scene must opt in to be accepted).
  const std::vector<std::string> unstable = {"body.distribution.per_edge=8", "material.young_modulus=2e8",
                                             "integrator.allow_unstable_dt=true"};
  {  // headless
    auto session = c.open(true, unstable);
    auto set = session.setForceRequest();
    set.setNewtons(100.0);
    set.send().wait(c.ws());
    for (int k = 0; k < 4; ++k) {
      auto step = session.stepRequest();
      step.setN(250);
      step.getFields().setPositions(true);
      auto frame_response = step.send().wait(c.ws());
      auto frame = frame_response.getFrame();
      EXPECT_TRUE(std::isfinite(frame.getIndenterContactForce()));
      // Caught by the health checks while still a body: no coordinate far outside the 2 m box.
      for (float x : frame.getPositions()) ASSERT_TRUE(std::isfinite(x) && std::abs(x) < 4.0f) << x;
    }
    auto status_response = session.statusRequest().send().wait(c.ws());
    auto status = status_response.getStatus();
    EXPECT_GE(status.getBlowUps(), 1u);
    EXPECT_NE(std::string(status.getLastBlowUp().cStr()).find("restored"), std::string::npos)
        << status.getLastBlowUp().cStr();
  }
  {  // real time, streamed with every field
    auto session = c.open(false, unstable);
    auto sink_owner = kj::heap<RecordingSink>();
    RecordingSink& sink = *sink_owner;
    auto sub = session.subscribeRequest();
    FrameSink::Client sink_cap = kj::mv(sink_owner);  // held here: the sink outlives the server's reference
    sub.setSink(sink_cap);
    sub.getOptions().setRateHz(0);
    sub.getOptions().getFields().setPositions(true);
    sub.getOptions().getFields().setContacts(true);
    auto handle = sub.send().wait(c.ws()).getSubscription();
    auto set = session.setForceRequest();
    set.setNewtons(100.0);
    set.send().wait(c.ws());
    c.pump(1000);
    auto status_response = session.statusRequest().send().wait(c.ws());
    auto status = status_response.getStatus();
    EXPECT_GE(status.getBlowUps(), 1u);
    EXPECT_EQ(status.getState(), palpate::wire::RunState::RUNNING);
    ASSERT_GT(sink.frames.size(), 100u);
    for (const auto& f : sink.frames) {
      ASSERT_TRUE(f.finite) << "non-finite frame at tick " << f.tick;
      // Caught by the health checks while still a body (the cube spans |x| <= 2 m).
      ASSERT_LT(f.largest_coordinate, 4.0f) << "frame at tick " << f.tick;
    }
  }
}

// Recoveries (a checkpoint restored) cost the loop little: the real-time session of
// BlowUpIsDetectedRecoveredAndNeverStreamed keeps half the rate of a healthy session, which
// a loaded machine does not fail and a loop stalled by its recoveries would.
TEST(ServerE2ETiming, BlowUpRecoveriesCostTheLoopLittle) {
  Client c;
  auto session = c.open(false, {"body.distribution.per_edge=8", "material.young_modulus=2e8",
                                "integrator.allow_unstable_dt=true"});
  auto set = session.setForceRequest();
  set.setNewtons(100.0);
  set.send().wait(c.ws());
  c.pump(1000);
  auto status_response = session.statusRequest().send().wait(c.ws());
  EXPECT_GE(status_response.getStatus().getBlowUps(), 1u) << "no recovery: the test proves nothing";
  EXPECT_GT(achieved_rate(c, session), kMinRateHz / 2);
}

// A client that subscribes to every tick with all positions and then never reads
// (its thread stops running its event loop), while another session is measured.
TEST(ServerE2ETiming, StalledAndVanishingClientsCostOthersNothing) {
  StalledSubscriber<Client> stalled;

  Client c;
  auto session = c.open(false);
  auto sink_owner = kj::heap<RecordingSink>();
  RecordingSink& sink = *sink_owner;
  auto sub = session.subscribeRequest();
  FrameSink::Client sink_cap = kj::mv(sink_owner);  // held here: the sink outlives the server's reference
  sub.setSink(sink_cap);
  sub.getOptions().setRateHz(0);
  auto handle = sub.send().wait(c.ws()).getSubscription();

  // Clients that vanish mid-stream (their connection closes with frames in flight).
  for (int k = 0; k < 3; ++k) {
    Client gone;
    auto s = gone.open(false);
    auto req = s.subscribeRequest();
    req.setSink(kj::heap<RecordingSink>());
    req.getOptions().setRateHz(0);
    req.getOptions().getFields().setPositions(true);
    auto h = req.send().wait(gone.ws()).getSubscription();
    gone.pump(100);
  }
  sink.frames.clear();
  c.pump(1500);
  const double rate = achieved_rate(c, session);
  stalled.release();
  EXPECT_GT(rate, kMinRateHz);
  expect_full_rate_delivery(sink.frames, "the full-rate subscriber beside a stalled neighbour");
  EXPECT_TRUE(g_server->alive());
}

TEST(ServerE2E, GarbageBytesAndConnectionChurn) {
  // Garbage on the port.
  for (int k = 0; k < 5; ++k) {
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<uint16_t>(g_server->port()));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
    std::mt19937 rng(k);
    std::vector<uint8_t> junk(k == 0 ? 8 : 65536);
    for (auto& b : junk) b = static_cast<uint8_t>(rng());
    if (k == 1) std::fill(junk.begin(), junk.begin() + 8, 0xff);  // an absurd segment count
    [[maybe_unused]] const ssize_t n = write(fd, junk.data(), junk.size());
    close(fd);
  }
  {
    Client c;
    EXPECT_EQ(c.server.versionRequest().send().wait(c.ws()).getProtocolVersion(), palpate::wire::PROTOCOL_VERSION);
  }
  // 100 connect / open / disconnect cycles; memory must not grow.
  auto cycle = [](int k) {
    Client c;
    if (k % 4 == 0) {
      auto s = c.open(k % 8 == 0);
      auto req = s.subscribeRequest();
      req.setSink(kj::heap<RecordingSink>());
      req.getOptions().setRateHz(200);
      req.getOptions().getFields().setPositions(true);
      auto h = req.send().wait(c.ws()).getSubscription();
      c.pump(5);
    } else {
      c.server.versionRequest().send().wait(c.ws());
    }
  };
  for (int k = 0; k < 20; ++k) cycle(k);  // warm-up: allocator pools
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const long rss_before = g_server->rss_kb();
  for (int k = 0; k < 100; ++k) cycle(k);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const long rss_after = g_server->rss_kb();
  std::printf("server RSS %ld kB -> %ld kB over 100 cycles\n", rss_before, rss_after);
  EXPECT_LT(rss_after - rss_before, kMaxRssGrowthKb) << "RSS grew by " << (rss_after - rss_before) << " kB";
  Client c;
  auto list_response = c.server.listScenesRequest().send().wait(c.ws());
  auto list = list_response.getNames();
  EXPECT_GE(list.size(), 1u);
  EXPECT_TRUE(g_server->alive());
}

// openSession validates, reads and builds on the session's thread: the RPC thread
// keeps serving everyone meanwhile, and a client that leaves while its session is
// still building costs nothing (no join on the RPC thread) and leaves nothing behind.
// One run of that: an unrelated client measures its worst version() round trip while a
// session builds and after its client left; the abandoned start must end by itself.
struct AbandonedStart {
  double while_building_ms = 0, after_leaving_ms = 0;
  bool thread_while_building = false;  // the session's thread existed while it built
  long baseline = 0, threads_after_leaving = 0, threads_at_end = 0;
};

AbandonedStart abandon_a_start_while_building(Client& other) {
  // The sessions of earlier tests close as the server notices their clients left.
  for (int k = 0; k < 100 && g_server->threads() > 1; ++k) other.pump(50);
  AbandonedStart r;
  r.baseline = g_server->threads();
  auto worst_round_trip = [&other](std::chrono::milliseconds window) {
    double worst = 0;
    const auto end = std::chrono::steady_clock::now() + window;
    while (std::chrono::steady_clock::now() < end) {
      const auto t0 = std::chrono::steady_clock::now();
      other.server.versionRequest().send().wait(other.ws());
      worst = std::max(worst, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      other.pump(5);
    }
    return worst;
  };
  {
    auto leaving = std::make_unique<Client>();
    auto req = leaving->server.openSessionRequest();
    auto rq = req.initRequest();
    rq.getScene().setName("hertz_cube_graded");  // consistent integration: about 2 s to build at 17^3
    rq.initOverrides(1).set(0, "body.distribution.per_edge=17");
    rq.setHeadless(true);
    auto pending = req.send();
    r.while_building_ms = worst_round_trip(std::chrono::milliseconds(300));
    r.thread_while_building = g_server->threads() > r.baseline;
    // The client goes, its openSession unanswered.
  }
  r.after_leaving_ms = worst_round_trip(std::chrono::milliseconds(300));
  r.threads_after_leaving = g_server->threads();
  // The abandoned start ends by itself and its thread is joined and freed.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (g_server->threads() > r.baseline && std::chrono::steady_clock::now() < deadline) other.pump(50);
  r.threads_at_end = g_server->threads();
  std::printf("worst version() round trip %.1f ms while a session builds, %.1f ms after its client left "
              "(%ld server threads then, %ld now)\n",
              r.while_building_ms, r.after_leaving_ms, r.threads_after_leaving, r.threads_at_end);
  return r;
}

TEST(ServerE2E, ASessionStillBuildingNeverBlocksOthersAndIsFreedWhenItsClientLeaves) {
  Client other;
  const AbandonedStart r = abandon_a_start_while_building(other);
  EXPECT_TRUE(r.thread_while_building) << "the session's thread is building";
  EXPECT_LE(r.threads_at_end, r.baseline) << "the abandoned session's thread was not freed";
  auto session = other.open(true);  // the server still opens sessions
  auto step = session.stepRequest();
  step.setN(5);
  EXPECT_EQ(step.send().wait(other.ws()).getFrame().getTick(), 5);
}

// Timing: the same, with the RPC thread's answers held to 250 ms throughout (a join on the
// RPC thread would cost the build's 2 s).
TEST(ServerE2ETiming, ASessionStillBuildingNeverDelaysOthers) {
  Client other;
  const AbandonedStart r = abandon_a_start_while_building(other);
  EXPECT_LT(r.while_building_ms, 250.0) << "the RPC thread waited for a session's start";
  EXPECT_LT(r.after_leaving_ms, 250.0) << "the RPC thread joined a session still building";
}

TEST(ServerE2E, ABrokenDefaultSceneStopsTheServerBeforeItListens) {
  SceneFolder folder;
  std::string nodes;
  for (int k = 0; k < 27; ++k)
    nodes += std::to_string(k % 3 - 1) + " " + std::to_string(k / 3 % 3 - 1) + " " + std::to_string(k / 9 - 2) + "\n";
  folder.write("cloud.txt", nodes);
  const struct {
    std::string file, expected;
    std::vector<std::string> extra;
  } cases[] = {
      {folder.write("poisson.json", R"({"material": {"poisson_ratio": 0.7}})"),
       "poisson.json: /material/poisson_ratio: must be a number in (-1, 0.5), got 0.7", {}},
      {folder.write("no_nodes.json", R"({"body": {"distribution": {"type": "node_file", "node_file": "gone.txt"}}})"),
       "no_nodes.json: /body/distribution/node_file: node file 'gone.txt' not found", {}},
      {folder.write("unstable.json", R"({"integrator": {"dt": 0.5}})"),
       "unstable.json: /integrator/dt: 0.5 s is outside the measured stable envelope", {}},
      {folder.write("too_many.json", R"({"body": {"distribution": {"type": "node_file", "node_file": "cloud.txt"}}})"),
       "cloud.txt' lists more than 8 nodes, this server's particle limit", {"--max-particles", "8"}},
      {folder.dir + "/absent.json", "absent.json: cannot read file", {}},
  };
  for (const auto& c : cases) {
    std::vector<std::string> args = {PALPATE_SERVER_BIN, "--listen", "127.0.0.1:0", "--scene", c.file};
    args.insert(args.end(), c.extra.begin(), c.extra.end());
    const ProgramResult r = run_program(args, std::chrono::seconds(60));
    EXPECT_EQ(r.status, 1) << c.file << ": " << r.err;
    EXPECT_EQ(r.out.find("listening"), std::string::npos) << c.file << ": " << r.out;
    EXPECT_NE(r.err.find("palpate-server: --scene: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(c.expected), std::string::npos) << "expected '" << c.expected << "' in: " << r.err;
  }
}

// ---------------------------------------------------------------------------
// The 3-D tool (protocol 2).

palpate::wire::Frame::Reader step_frame(Client& c, Session::Client& s, uint32_t n,
                                        kj::Own<capnp::Response<Session::StepResults>>& keep) {
  auto req = s.stepRequest();
  req.setN(n);
  keep = kj::heap(req.send().wait(c.ws()));
  return keep->getFrame();
}

double distance(palpate::wire::Vec3::Reader a, double x, double y, double z) {
  return std::sqrt(std::pow(a.getX() - x, 2) + std::pow(a.getY() - y, 2) + std::pow(a.getZ() - z, 2));
}

TEST(ServerE2E, PositionCommandsDriveTheToolThroughTheCoupling) {
  Client c;
  auto session = c.open_free(true);
  auto info_response = session.infoRequest().send().wait(c.ws());
  auto info = info_response.getInfo();
  EXPECT_EQ(info.getGuide(), palpate::wire::ToolGuide::FREE);
  ASSERT_GT(info.getCoupling().getStiffness(), 0.0);  // the default coupling
  ASSERT_GT(info.getCoupling().getDamping(), 0.0);
  const double top = info.getTouchHeight() - info.getRadius();  // z of the top face
  const double R = info.getRadius();

  // In the air: the tool goes to the device position and nothing is rendered.
  const double ax = 0.2, ay = -0.1, az = info.getTouchHeight() + 0.3;
  auto to = session.setPositionRequest();
  to.initPosition().setX(ax);
  to.getPosition().setY(ay);
  to.getPosition().setZ(az);
  to.send().wait(c.ws());
  kj::Own<capnp::Response<Session::StepResults>> keep;
  auto air = step_frame(c, session, 3000, keep);
  EXPECT_EQ(air.getMode(), palpate::wire::ControlMode::POSITION);
  EXPECT_LT(distance(air.getIndenterPosition(), ax, ay, az), 1e-4 * R);
  EXPECT_LT(distance(air.getRenderForce(), 0, 0, 0), 1e-6);
  EXPECT_EQ(air.getToolContactForce().getZ(), 0.0);

  // Pressed 0.1 R below first touch at (ax, ay): at rest the coupling balances the
  // contact, so the rendered force is the contact force (pushing the device up).
  auto press = session.setPositionRequest();
  press.initPosition().setX(ax);
  press.getPosition().setY(ay);
  press.getPosition().setZ(info.getTouchHeight() - 0.1 * R);
  press.send().wait(c.ws());
  auto held = step_frame(c, session, 6000, keep);
  const double fz = held.getToolContactForce().getZ();
  EXPECT_GT(fz, 0.0);
  EXPECT_NEAR(held.getRenderForce().getZ(), fz, 0.01 * fz);
  EXPECT_NEAR(held.getRenderForce().getX(), held.getToolContactForce().getX(), 0.01 * fz);
  EXPECT_LT(std::abs(held.getIndenterPosition().getX() - ax), 0.01 * R);  // frictionless: no lateral drift
  EXPECT_LT(held.getIndenterPosition().getZ(), info.getTouchHeight());
  EXPECT_GT(held.getIndenterPosition().getZ(), top);

  // The local models of that frame: a contact stiffness of the frame's own state
  // (headless: computed at the publish), restoring along z; the render model predicts
  // the rendered force at a nearby device position, against the full steps to rest there.
  auto contact_model = held.getContactModel();
  EXPECT_EQ(contact_model.getStiffnessTick(), held.getTick());
  EXPECT_LT(contact_model.getStiffness()[8], 0.0);  // dFz/dz
  EXPECT_GT(contact_model.getValidRadius(), 0.0);
  auto render = held.getRenderModel();
  const double k = info.getCoupling().getStiffness();
  const double kzz = render.getStiffness()[8];
  EXPECT_LT(kzz, 0.0);
  EXPECT_GT(kzz, -k);  // in series with the coupling: softer than the spring alone
  const double dz = -0.02 * R;
  const double predicted = render.getForce().getZ() + kzz * dz;
  const double f0 = render.getForce().getZ();
  auto deeper = session.setPositionRequest();
  deeper.initPosition().setX(ax);
  deeper.getPosition().setY(ay);
  deeper.getPosition().setZ(info.getTouchHeight() - 0.1 * R + dz);
  deeper.send().wait(c.ws());
  kj::Own<capnp::Response<Session::StepResults>> keep_deeper;
  const double full = step_frame(c, session, 6000, keep_deeper).getRenderForce().getZ();
  EXPECT_LT(std::abs(predicted - full), 0.2 * std::abs(full - f0))
      << "render model " << predicted << " N, full steps " << full << " N, zero-order hold " << f0 << " N";
  auto back = session.setPositionRequest();
  back.initPosition().setX(ax);
  back.getPosition().setY(ay);
  back.getPosition().setZ(info.getTouchHeight() - 0.1 * R);
  back.send().wait(c.ws());
  held = step_frame(c, session, 6000, keep);

  // Refused commands name the field and change nothing.
  const double wx = info.getWorkspaceMax().getX();
  for (auto bad : std::vector<std::array<double, 3>>{{std::nan(""), 0, 0}, {wx + 0.01, 0, az}, {0, 0, HUGE_VAL}}) {
    auto req = session.setPositionRequest();
    req.initPosition().setX(bad[0]);
    req.getPosition().setY(bad[1]);
    req.getPosition().setZ(bad[2]);
    EXPECT_NE(c.error_of(req).find("setPosition: position"), std::string::npos);
  }
  const double limit = info.getForceLimit();
  for (auto bad : std::vector<std::array<double, 3>>{{0, std::nan(""), 0}, {limit, limit, 0}, {0, 0, -HUGE_VAL}}) {
    auto req = session.setForceVectorRequest();
    req.initForce().setX(bad[0]);
    req.getForce().setY(bad[1]);
    req.getForce().setZ(bad[2]);
    EXPECT_NE(c.error_of(req).find("setForceVector: force"), std::string::npos);
  }
  auto after = step_frame(c, session, 1, keep);
  EXPECT_EQ(after.getMode(), palpate::wire::ControlMode::POSITION);
  EXPECT_EQ(after.getTarget().getX(), ax);
  EXPECT_EQ(after.getTarget().getZ(), info.getTouchHeight() - 0.1 * R);

  // A force vector: force mode again, the command as sent.
  auto push = session.setForceVectorRequest();
  push.initForce().setX(0.0);
  push.getForce().setY(0.0);
  push.getForce().setZ(-20.0);
  push.send().wait(c.ws());
  auto forced = step_frame(c, session, 1, keep);
  EXPECT_EQ(forced.getMode(), palpate::wire::ControlMode::FORCE);
  EXPECT_EQ(forced.getForceVector().getZ(), -20.0);
  EXPECT_EQ(forced.getForceCommand(), 20.0);  // the pressing scalar
}

TEST(ServerE2E, DeviceLimitsClampTheCouplingAndTheRenderedForce) {
  Client c;
  auto session = c.open_free(true, 300.0, 2.0, 1.5, 1e6, 1e3);
  auto info_response = session.infoRequest().send().wait(c.ws());
  auto info = info_response.getInfo();
  EXPECT_EQ(info.getCoupling().getStiffness(), 300.0);
  EXPECT_EQ(info.getCoupling().getDamping(), 2.0);
  EXPECT_EQ(info.getDevice().getMaxForce(), 1.5);
  auto set = session.setCouplingRequest();
  set.initCoupling().setStiffness(100.0);
  set.getCoupling().setDamping(50.0);
  auto applied = set.send().wait(c.ws());
  EXPECT_EQ(applied.getCoupling().getStiffness(), 100.0);
  EXPECT_EQ(applied.getCoupling().getDamping(), 2.0);
  auto negative = session.setCouplingRequest();
  negative.initCoupling().setStiffness(-1.0);
  EXPECT_NE(c.error_of(negative).find("setCoupling: coupling.stiffness"), std::string::npos);

  // Deep below the surface: k x 0.5 m = 50 N wanted, 1.5 N rendered at most.
  auto press = session.setPositionRequest();
  press.initPosition().setX(0.0);
  press.getPosition().setY(0.0);
  press.getPosition().setZ(info.getTouchHeight() - 0.5);
  press.send().wait(c.ws());
  kj::Own<capnp::Response<Session::StepResults>> keep;
  auto f = step_frame(c, session, 200, keep);
  EXPECT_TRUE(f.getForceSaturated());
  EXPECT_NEAR(distance(f.getRenderForce(), 0, 0, 0), 1.5, 1e-9);

  // Refused device limits name the field.
  auto req = c.server.openSessionRequest();
  req.initRequest().initDevice().setMaxStiffness(-5.0);
  EXPECT_NE(c.error_of(req).find("request.device.maxStiffness"), std::string::npos);
}

TEST(ServerE2E, CancelAndCloseEndStreamsWithDone) {
  Client c;
  auto session = c.open(false);
  std::vector<FrameSink::Client> sinks;  // held here: the sinks outlive the server's references
  auto subscribe = [&](RecordingSink*& out) {
    auto owner = kj::heap<RecordingSink>();
    out = owner.get();
    sinks.push_back(kj::mv(owner));
    auto sub = session.subscribeRequest();
    sub.setSink(sinks.back());
    sub.getOptions().setRateHz(200);
    return sub.send().wait(c.ws()).getSubscription();
  };
  RecordingSink *a = nullptr, *b = nullptr;
  auto handle_a = subscribe(a);
  auto handle_b = subscribe(b);  // both handles kept: only cancel() and close() may end them
  c.pump(200);
  ASSERT_GT(a->frames.size(), 5u);
  handle_a.cancelRequest().send().wait(c.ws());
  c.pump(50);
  EXPECT_TRUE(a->finished);
  const size_t after_cancel = a->frames.size();
  handle_a.cancelRequest().send().wait(c.ws());  // idempotent
  c.pump(100);
  EXPECT_EQ(a->frames.size(), after_cancel);
  EXPECT_FALSE(b->finished);
  EXPECT_GT(b->frames.size(), after_cancel / 2);

  session.closeRequest().send().wait(c.ws());
  c.pump(50);
  EXPECT_TRUE(b->finished);
  auto set = session.setForceRequest();
  set.setNewtons(1.0);
  EXPECT_NE(c.error_of(set).find("the session is closed"), std::string::npos);
  EXPECT_TRUE(session.statusRequest().send().wait(c.ws()).getStatus().getClosed());
  const int64_t tick = session.statusRequest().send().wait(c.ws()).getStatus().getTick();
  c.pump(50);
  EXPECT_EQ(session.statusRequest().send().wait(c.ws()).getStatus().getTick(), tick);  // the loop stopped
  session.closeRequest().send().wait(c.ws());  // idempotent
}

TEST(ServerE2E, ShutdownDeliversDoneToEverySubscriber) {
  ServerProcess own;
  Client c(own.address());
  auto session = c.open(false);
  auto owner = kj::heap<RecordingSink>();
  RecordingSink& sink = *owner;
  FrameSink::Client sink_cap = kj::mv(owner);  // held here: the sink outlives the server's reference
  auto sub = session.subscribeRequest();
  sub.setSink(sink_cap);
  sub.getOptions().setRateHz(100);
  auto handle = sub.send().wait(c.ws()).getSubscription();
  c.pump(100);
  ASSERT_FALSE(sink.frames.empty());
  kill(own.pid(), SIGTERM);
  for (int k = 0; k < 100 && !sink.finished; ++k) c.pump(20);
  EXPECT_TRUE(sink.finished) << "no FrameSink.done before the server exited";
  EXPECT_EQ(own.terminate(std::chrono::seconds(5)), 0);
}

// palpate-client --haptic-rate against the test server: a coarse hertz_cube (top face
// z = 0, R = 0.5 m, so first touch at z = 0.5 and the default depth R/5 puts the device at
// z = 0.4 when it holds), the tool freed by the client. It runs the palpation path, exits
// 0, prints the summary, and its CSV shows the device pressing and a force pushing it up.
TEST(ServerE2E, HapticClientPalpatesAndReports) {
#ifdef PALPATE_SANITIZED
  const std::string servo_hz = "1000";  // the sanitized client and server are several times slower
#else
  const std::string servo_hz = "2000";
#endif
  SceneFolder folder;
  const std::string csv = folder.dir + "/haptic.csv";
  const ProgramResult r = run_program({PALPATE_CLIENT_BIN, "--connect", g_server->address(), "--scene", "hertz_cube",
                                       "--set", "body.distribution.per_edge=8", "--haptic-rate", servo_hz,
                                       "--seconds", "1", "--csv", csv},
                                      std::chrono::seconds(60));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  for (const char* line : {"command->force    p50", "tick lateness     p50", "servo loop", "rendering error",
                           "  slide A-B", "  all "})
    EXPECT_NE(r.out.find(line), std::string::npos) << line << "\n" << r.out;
  unsigned matched = 0, sent = 0;
  const auto at = r.out.find("ms (");
  ASSERT_NE(at, std::string::npos) << r.out;
  ASSERT_EQ(std::sscanf(r.out.c_str() + at, "ms (%u of %u setPosition matched)", &matched, &sent), 2) << r.out;
  EXPECT_GT(sent, 300u);  // one per tick of a 1 kHz loop for 1 s, a live one even when sanitized
  EXPECT_GE(matched, sent * 9 / 10);

  std::ifstream in(csv);
  std::string header;
  ASSERT_TRUE(std::getline(in, header));
  EXPECT_EQ(header.rfind("time_s,segment,device_x_m,device_y_m,device_z_m,rendered_fx_n", 0), 0u) << header;
  size_t rows = 0;
  double lowest = HUGE_VAL, strongest = -HUGE_VAL;
  for (std::string line; std::getline(in, line); ++rows) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) cells.push_back(cell);
    ASSERT_EQ(cells.size(), 15u) << line;
    lowest = std::min(lowest, std::stod(cells[4]));
    strongest = std::max(strongest, std::stod(cells[7]));
  }
  EXPECT_GT(rows, static_cast<size_t>(std::stod(servo_hz) / 4));  // the servo ticks of 1 s, many skipped at worst
  EXPECT_NEAR(lowest, 0.4, 1e-9);   // holding at R/5 below first touch
  EXPECT_GT(strongest, 1.0);        // the body pushes the device up (N)
}

// The network programs share the argument helper (cli/arguments.h): --help prints the
// whole usage on stdout and exits 0; garbage values are refused with exit 2.
TEST(ServerE2E, ProgramsPrintTheirUsageAndRefuseGarbage) {
  const struct {
    std::string bin, name;
  } programs[] = {{PALPATE_SERVER_BIN, "palpate-server"},
                  {PALPATE_CLIENT_BIN, "palpate-client"},
                  {PALPATE_BENCH_SERVER_BIN, "palpate-bench-server"},
                  {PALPATE_BENCH_HAPTIC_BIN, "palpate-bench-haptic"}};
  for (const auto& p : programs) {
    for (const std::string help : {"--help", "-h"}) {
      const ProgramResult r = run_program({p.bin, help}, std::chrono::seconds(20));
      EXPECT_EQ(r.status, 0) << p.name << " " << help << ": " << r.err;
      EXPECT_EQ(r.out.rfind("usage: " + p.name + " [options]\n", 0), 0u) << r.out;
      EXPECT_NE(r.out.find("--rate HZ"), std::string::npos) << r.out;
      EXPECT_NE(r.out.find("Exit status"), std::string::npos) << r.out;
      EXPECT_EQ(r.err, "");
    }
    const ProgramResult garbage = run_program({p.bin, "--rate", "abc"}, std::chrono::seconds(20));
    EXPECT_EQ(garbage.status, 2) << p.name;
    EXPECT_EQ(garbage.err.rfind(p.name + ": --rate: 'abc' is not a number\n\nusage: " + p.name, 0), 0u)
        << garbage.err;
    EXPECT_EQ(garbage.out, "");
    const ProgramResult unknown = run_program({p.bin, "--frobnicate"}, std::chrono::seconds(20));
    EXPECT_EQ(unknown.status, 2) << p.name;
    EXPECT_NE(unknown.err.find("unknown option '--frobnicate'"), std::string::npos) << unknown.err;
    const ProgramResult missing = run_program({p.bin, "--rate"}, std::chrono::seconds(20));
    EXPECT_EQ(missing.status, 2) << p.name;
    EXPECT_NE(missing.err.find("--rate needs a value"), std::string::npos) << missing.err;
  }
  const ProgramResult client_help = run_program({PALPATE_CLIENT_BIN, "--help"}, std::chrono::seconds(20));
  EXPECT_NE(client_help.out.find("--haptic-rate HZ"), std::string::npos) << client_help.out;
  const ProgramResult haptic_rate = run_program({PALPATE_CLIENT_BIN, "--haptic-rate", "0"}, std::chrono::seconds(20));
  EXPECT_EQ(haptic_rate.status, 2);
  EXPECT_NE(haptic_rate.err.find("--haptic-rate: must be in (0, 100000] Hz"), std::string::npos) << haptic_rate.err;
  const ProgramResult steps = run_program({PALPATE_CLIENT_BIN, "--max-steps", "1.5"}, std::chrono::seconds(20));
  EXPECT_EQ(steps.status, 2);
  EXPECT_NE(steps.err.find("--max-steps: '1.5' is not an integer"), std::string::npos) << steps.err;
  const ProgramResult seconds = run_program({PALPATE_BENCH_SERVER_BIN, "--seconds", "3s"}, std::chrono::seconds(20));
  EXPECT_EQ(seconds.status, 2);
  EXPECT_NE(seconds.err.find("--seconds: '3s' is not a number"), std::string::npos) << seconds.err;
  const ProgramResult level = run_program({PALPATE_SERVER_BIN, "--log-level", "loud"}, std::chrono::seconds(20));
  EXPECT_EQ(level.status, 2);
  EXPECT_NE(level.err.find("--log-level: 'loud' is not one of"), std::string::npos) << level.err;
}

// ---------------------------------------------------------------------------
// The same protocol over WebSocket (palpate-server --http: /rpc).

// Random bytes for the WebSocket handshake key and the client's frame masks.
// A Cap'n Proto client over ws://127.0.0.1:WEB/rpc with its own event loop (one per
// thread): tests/e2e/ws_client.h on it.
struct WsClient {
  explicit WsClient(const std::string& origin = "")
      : io(kj::setupAsyncIo()), connection(io, g_server->web_port(), origin), status(connection.status),
        server(connection.server) {}
  kj::WaitScope& ws() { return io.waitScope; }
  void pump(int ms) { io.provider->getTimer().afterDelay(ms * kj::MILLISECONDS).wait(ws()); }

  kj::AsyncIoContext io;
  palpate::test::WsRpcConnection connection;
  unsigned status = 0;  // of the upgrade: 101 when accepted
  PalpateServer::Client server = nullptr;
};

// A raw connection to the web port: bytes in, bytes out, with a timeout.
struct RawSocket {
  RawSocket() {
    fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<uint16_t>(g_server->web_port()));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) std::abort();
  }
  ~RawSocket() { close(fd); }
  void send(const std::string& bytes) const {
    size_t sent = 0;
    while (sent < bytes.size()) {
      const ssize_t n = ::send(fd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) return;  // the server closed: fine, the caller checks what it read
      sent += static_cast<size_t>(n);
    }
  }
  // Everything until the peer closes or `ms` pass (or, with headers_only, until the end
  // of a response's headers).
  std::string read_all(int ms, bool headers_only = false) const {
    std::string got;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    while (std::chrono::steady_clock::now() < deadline) {
      if (headers_only && got.find("\r\n\r\n") != std::string::npos) break;
      pollfd p{fd, POLLIN, 0};
      if (poll(&p, 1, 20) <= 0) continue;
      char buf[4096];
      const ssize_t n = recv(fd, buf, sizeof buf, 0);
      if (n <= 0) break;
      got.append(buf, static_cast<size_t>(n));
    }
    return got;
  }
  int fd;
};

std::string upgrade_request(const std::string& path, const std::string& origin) {
  std::string r = "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1:" + std::to_string(g_server->web_port()) +
                  "\r\nConnection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\n"
                  "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
  if (!origin.empty()) r += "Origin: " + origin + "\r\n";
  return r + "\r\n";
}

// A masked client frame (RFC 6455 5.2) with `length` bytes of `payload` (repeated).
std::string client_frame(uint8_t opcode, const std::string& payload, size_t length) {
  std::string f;
  f += static_cast<char>(0x80 | opcode);
  if (length < 126) {
    f += static_cast<char>(0x80 | length);
  } else if (length < 65536) {
    f += static_cast<char>(0x80 | 126);
    f += static_cast<char>(length >> 8);
    f += static_cast<char>(length & 0xff);
  } else {
    f += static_cast<char>(0x80 | 127);
    for (int k = 7; k >= 0; --k) f += static_cast<char>((static_cast<uint64_t>(length) >> (8 * k)) & 0xff);
  }
  f += std::string("\x12\x34\x56\x78", 4);
  for (size_t k = 0; k < length; ++k) f += static_cast<char>(payload[k % payload.size()] ^ "\x12\x34\x56\x78"[k % 4]);
  return f;
}

// The loop runs where the server put it (unpinned: the default), and every deadline miss
// is counted under one cause: a late start or a long step.
// Multirate (OpenRequest.hapticRateHz): the model steps at 100 Hz, the server renders at
// 500 Hz. The stream carries a frame per render tick (several per step), each with its
// render tick and the age of the step it was rendered from; a device position sent between
// steps is in the next render's target and commandSeq before any step applies it.
TEST(ServerE2E, MultirateFramesComeAtTheRenderRateFromTheNewestStep) {
  struct Seen {
    int64_t tick, haptic_tick, model_age_ns;
    uint64_t seq;
    double target_z;
  };
  struct Sink final : public palpate::wire::FrameSink::Server {
    explicit Sink(std::vector<Seen>& s) : seen(s) {}
    kj::Promise<void> frame(FrameContext context) override {
      auto f = context.getParams().getFrame();
      seen.push_back({f.getTick(), f.getHapticTick(), f.getModelAgeNs(), f.getCommandSeq(), f.getTarget().getZ()});
      return kj::READY_NOW;
    }
    kj::Promise<void> done(DoneContext) override { return kj::READY_NOW; }
    std::vector<Seen>& seen;
  };
  Client c;
  auto open = [&](double rate, double haptic_rate, bool headless) {
    auto req = c.server.openSessionRequest();
    auto r = req.initRequest();
    r.getScene().setName("hertz_cube");
    auto o = r.initOverrides(2);
    o.set(0, "body.distribution.per_edge=8");
    o.set(1, "indenter.guide=free");
    r.setHeadless(headless);
    r.setRateHz(rate);
    r.setHapticRateHz(haptic_rate);
    return req;
  };
  // Refused: below the model's rate, above 10 kHz, headless, not a number.
  EXPECT_NE(c.error_of(open(100, 50, false)).find("request.hapticRateHz"), std::string::npos);
  EXPECT_NE(c.error_of(open(100, 20000, false)).find("request.hapticRateHz"), std::string::npos);
  EXPECT_NE(c.error_of(open(100, 500, true)).find("headless"), std::string::npos);
  EXPECT_NE(c.error_of(open(100, std::nan(""), false)).find("request.hapticRateHz"), std::string::npos);

  auto opened = open(100, 500, false).send().wait(c.ws());
  auto session = opened.getSession();
  EXPECT_EQ(opened.getInfo().getHapticRateHz(), 500.0);
  const double touch = opened.getInfo().getTouchHeight();
  std::vector<Seen> seen;
  seen.reserve(100000);
  auto sub = session.subscribeRequest();
  sub.setSink(kj::heap<Sink>(seen));
  sub.getOptions().setRateHz(0);
  auto handle = sub.send().wait(c.ws()).getSubscription();
  c.pump(1000);
  auto to = session.setPositionRequest();
  to.initPosition().setX(0.0);
  to.getPosition().setY(0.0);
  to.getPosition().setZ(touch + 0.05);
  const uint64_t seq = to.send().wait(c.ws()).getSeq();
  c.pump(500);
  auto stats_response = session.statsRequest().send().wait(c.ws());
  auto stats = stats_response.getStats();
  EXPECT_EQ(stats.getHapticRateHz(), 500.0);
  EXPECT_GT(stats.getHapticTicks(), 0);
  EXPECT_EQ(stats.getTargetRateHz(), 100.0);
  handle = nullptr;
  c.pump(50);

  ASSERT_GT(seen.size(), 10u);
  std::set<int64_t> steps, renders;
  bool ordered = true;
  for (size_t k = 0; k < seen.size(); ++k) {
    EXPECT_GE(seen[k].haptic_tick, 0);
    EXPECT_GE(seen[k].model_age_ns, 0);
    steps.insert(seen[k].tick);
    renders.insert(seen[k].haptic_tick);
    if (k > 0) ordered = ordered && seen[k].haptic_tick > seen[k - 1].haptic_tick;
  }
  EXPECT_TRUE(ordered);
  EXPECT_GE(renders.size(), 2 * steps.size()) << "several renders per step (" << renders.size() << " renders of "
                                               << steps.size() << " steps)";
  // The first frame that includes the setPosition renders at its target.
  const auto first = std::find_if(seen.begin(), seen.end(), [&](const Seen& s) { return s.seq >= seq; });
  ASSERT_NE(first, seen.end());
  EXPECT_EQ(first->target_z, touch + 0.05);
  // And so does every later frame (no command follows). Which command a frame names when its
  // render is older than its step is pinned without the race in tests/server_frames_test.cpp.
  for (auto k = first; k != seen.end(); ++k)
    ASSERT_EQ(k->target_z, touch + 0.05) << "render tick " << k->haptic_tick << " of step " << k->tick;
  std::printf("multirate: %zu frames of %zu render ticks over %zu steps; stats: %lld render ticks, %llu misses, "
              "model age p50 %.0f us p99 %.0f us\n",
              seen.size(), renders.size(), steps.size(), static_cast<long long>(stats.getHapticTicks()),
              static_cast<unsigned long long>(stats.getHapticMisses()), stats.getModelAgeUs().getP50(),
              stats.getModelAgeUs().getP99());
}

TEST(ServerE2E, EveryMissHasACauseAndPinningIsReported) {
  {
    Client c;
    auto session = c.open(false);
    c.pump(1000);
    auto stats_response = session.statsRequest().send().wait(c.ws());
    auto stats = stats_response.getStats();
    EXPECT_FALSE(stats.getPinned()) << "the test's server runs without --pin";
    EXPECT_EQ(stats.getMissesLateStart() + stats.getMissesLongStep(), stats.getDeadlineMisses());
    std::printf("1 s at 1 kHz: %llu misses (%llu late starts, %llu long steps), pinned %d\n",
                static_cast<unsigned long long>(stats.getDeadlineMisses()),
                static_cast<unsigned long long>(stats.getMissesLateStart()),
                static_cast<unsigned long long>(stats.getMissesLongStep()), stats.getPinned());
  }  // the session ends with its client
  // A server asked to pin: the loop runs on a core of its own where there are two. At
  // 100 Hz, so that even a sanitized step leaves the loop time to sleep (a SCHED_FIFO loop
  // that never sleeps on its core, beside another on the other core, starves everything else).
  palpate::test::ServerProcess pinning({"--pin", "--rate", "100"});
  bool pinned = false;
  std::thread([&] {  // one event loop per thread
    Client p(pinning.address());
    auto s = p.open(false);
    p.pump(300);
    pinned = s.statsRequest().send().wait(p.ws()).getStats().getPinned();
  }).join();
  EXPECT_EQ(pinned, std::thread::hardware_concurrency() >= 2);
}

TEST(ServerWebSocket, TheSameProtocolAndTheSameFramesAsTcp) {
  // A headless session over each transport: the frames are the same bytes.
  auto headless_frames = [](PalpateServer::Client& server, kj::WaitScope& ws) {
    auto session = open_session(server, ws, true);
    auto force = session.setForceRequest();
    force.setNewtons(60.0);
    force.send().wait(ws);
    std::vector<std::vector<uint8_t>> frames;
    for (int k = 0; k < 3; ++k) {
      auto step = session.stepRequest();
      step.setN(50);
      step.initFields().setPositions(true);
      frames.push_back(frame_bytes(step.send().wait(ws).getFrame()));
    }
    session.closeRequest().send().wait(ws);
    return frames;
  };
  std::vector<std::vector<uint8_t>> over_tcp;
  std::thread([&] {  // one event loop per thread: the TCP client in a thread of its own
    Client tcp;
    over_tcp = headless_frames(tcp.server, tcp.ws());
  }).join();
  WsClient w;
  ASSERT_EQ(w.status, 101u);
  EXPECT_EQ(w.server.versionRequest().send().wait(w.ws()).getProtocolVersion(), palpate::wire::PROTOCOL_VERSION);
  const auto over_ws = headless_frames(w.server, w.ws());
  ASSERT_EQ(over_tcp.size(), over_ws.size());
  for (size_t k = 0; k < over_tcp.size(); ++k) EXPECT_EQ(over_tcp[k], over_ws[k]) << "frame " << k;
  // Validation is the same: a NaN force is refused with the field's name.
  auto req = w.server.openSessionRequest();
  req.initRequest().getScene().setName("hertz_cube");
  auto session = req.send().wait(w.ws()).getSession();
  auto bad = session.setForceRequest();
  bad.setNewtons(std::nan(""));
  try {
    bad.send().wait(w.ws());
    ADD_FAILURE() << "a NaN force was accepted over WebSocket";
  } catch (const kj::Exception& e) {
    EXPECT_NE(std::string(e.getDescription().cStr()).find("setForce"), std::string::npos) << e.getDescription().cStr();
  }
}

TEST(ServerWebSocket, OriginPathAndStaticFilesAreChecked) {
  {  // another site's page may not open sessions
    WsClient evil("http://evil.example");
    EXPECT_EQ(evil.status, 403u);
  }
  {  // the server's own pages may
    WsClient own("http://127.0.0.1:" + std::to_string(g_server->web_port()));
    EXPECT_EQ(own.status, 101u);
  }
  RawSocket wrong_path;
  wrong_path.send(upgrade_request("/other", ""));
  EXPECT_NE(wrong_path.read_all(2000, true).find("404"), std::string::npos);
  for (const char* path : {"/../../etc/passwd", "/%2e%2e/etc/passwd", "/viewer.js/..", "//etc/passwd"}) {
    RawSocket s;
    s.send(std::string("GET ") + path + " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
    const std::string reply = s.read_all(2000, true);
    EXPECT_EQ(reply.rfind("HTTP/1.1 404", 0), 0u) << path << ": " << reply.substr(0, 80);
  }
  RawSocket health;
  health.send("GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
  EXPECT_EQ(health.read_all(2000, true).rfind("HTTP/1.1 200", 0), 0u);
  RawSocket post;
  post.send("POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 3\r\nConnection: close\r\n\r\nabc");
  EXPECT_EQ(post.read_all(2000, true).rfind("HTTP/1.1 405", 0), 0u);
}

// A full-rate subscriber (every tick, scalars only) over WebSocket on a session of its own.
struct WsFullRateSubscriber {
  WsFullRateSubscriber() : session(open_session(client.server, client.ws(), false)) {
    auto owner = kj::heap<RecordingSink>();
    sink = owner.get();
    sink_cap = kj::mv(owner);
    auto sub = session.subscribeRequest();
    sub.setSink(sink_cap);
    sub.getOptions().setRateHz(0);
    handle = sub.send().wait(client.ws()).getSubscription();
  }
  double achieved_rate() { return session.statsRequest().send().wait(client.ws()).getStats().getAchievedRateHz(); }
  WsClient client;
  Session::Client session;
  RecordingSink* sink = nullptr;
  FrameSink::Client sink_cap = nullptr;  // held here: the sink outlives the server's reference
  palpate::wire::Subscription::Client handle = nullptr;
};

// Bytes that are not WebSocket, not Cap'n Proto, or too large end their own connection
// only: a subscriber keeps getting finite frames, and both transports still answer. (No
// wall-clock threshold: this one runs under the sanitizers too.)
TEST(ServerWebSocket, GarbageAndOversizedMessagesEndOnlyTheirConnection) {
  WsFullRateSubscriber c;
  std::mt19937 rng(7);
  auto junk = [&](size_t n) {
    std::string s(n, '\0');
    for (auto& b : s) b = static_cast<char>(rng());
    return s;
  };
  {  // garbage before any handshake
    RawSocket s;
    s.send(junk(4096));
    s.read_all(500);
  }
  {  // a handshake, then binary frames that are not capnp messages, then a text frame
    RawSocket s;
    s.send(upgrade_request("/rpc", ""));
    s.send(client_frame(0x2, junk(64), 64));
    s.send(client_frame(0x2, std::string(8, '\xff'), 8));  // an absurd segment count
    s.send(client_frame(0x1, "hello", 5));
    s.read_all(500);
  }
  {  // an oversized message (2 MiB > the 1 MiB limit)
    RawSocket s;
    s.send(upgrade_request("/rpc", ""));
    s.send(client_frame(0x2, junk(4096), 2u << 20));
    s.read_all(500);
  }
  {  // a frame header announcing 2^62 bytes, and nothing after it
    RawSocket s;
    s.send(upgrade_request("/rpc", ""));
    std::string header = "\x82\xff";
    header += std::string("\x40\0\0\0\0\0\0\0", 8);
    s.send(header + "abcd");
    s.read_all(500);
  }
  c.sink->frames.clear();
  c.client.pump(300);
  EXPECT_GT(c.sink->frames.size(), 0u) << "the subscriber's stream stopped";
  for (const auto& f : c.sink->frames) EXPECT_TRUE(f.finite);
  EXPECT_TRUE(g_server->alive());
  uint32_t tcp_version = 0, ws_version = 0;
  std::thread([&] {  // one event loop per thread
    Client tcp;
    tcp_version = tcp.server.versionRequest().send().wait(tcp.ws()).getProtocolVersion();
  }).join();
  std::thread([&] {
    WsClient after;
    ws_version = after.server.versionRequest().send().wait(after.ws()).getProtocolVersion();
  }).join();
  EXPECT_EQ(tcp_version, palpate::wire::PROTOCOL_VERSION);
  EXPECT_EQ(ws_version, palpate::wire::PROTOCOL_VERSION);
}

// A WebSocket client that subscribes to every tick's positions and never reads costs a
// full-rate WebSocket subscriber of another session nothing (the wall-clock twin of
// StalledAndVanishingClientsCostOthersNothing; like it, left out of sanitized runs).
TEST(ServerWebSocketTiming, ANeverReadingClientCostsOthersNothing) {
  StalledSubscriber<WsClient> stalled;
  WsFullRateSubscriber c;
  c.sink->frames.clear();
  c.client.pump(1500);
  const double rate = c.achieved_rate();
  stalled.release();
  EXPECT_GT(rate, kMinRateHz);
  expect_full_rate_delivery(c.sink->frames, "a WebSocket subscriber beside a stalled neighbour");
  EXPECT_TRUE(g_server->alive());
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ::testing::AddGlobalTestEnvironment(new ServerEnvironment);
  return RUN_ALL_TESTS();
}
