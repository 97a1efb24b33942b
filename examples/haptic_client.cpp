// palpate-example-haptic-client: a haptic device loop against palpate-server, position in and
// force out every millisecond (docs/guide/haptic-device.md). The device is simulated.
#include <time.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>
#include <string>
#include <thread>

#include "cli/arguments.h"
#include "clients/connect.h"
#include "protocol/local_model.h"
#include "protocol/palpate.capnp.h"

namespace {

namespace wire = palpate::wire;
using V3 = std::array<double, 3>;

const char* kUsage = R"(usage: palpate-example-haptic-client [options]
Plays a simulated haptic device on a real-time session for --seconds: every 1 ms it sends the
device position and renders the force from the newest frame's render model.
  --connect ADDR:PORT       the server (default 127.0.0.1:7420)
  --scene NAME              a scene of the server's --scene-dir (default palpation_block; "": its default)
  --seconds S               length of the path, [0.001, 3600] (default 2)
  --tls-ca FILE             connect over TLS, trusting the PEM certificate(s) in FILE
  --access-token-file FILE  authenticate with the token in FILE
Exit status: 0 when done; 1 when the connection fails or the server refuses; 2 for a wrong argument.
)";

// The device's limits, sent at open: the server clamps the virtual coupling to them and
// saturates renderForce, and we saturate what we render the same way. A desktop arm's
// order of magnitude: put your device's own here.
constexpr double kMaxStiffness = 1000.0;  // N/m
constexpr double kMaxDamping = 5.0;       // N s/m
constexpr double kMaxForce = 3.3;         // N

V3 vec(wire::Vec3::Reader v) { return {v.getX(), v.getY(), v.getZ()}; }

// The newest frame, as far as the loop needs it. The sink writes it inside ws.poll(), on the
// loop's own thread: nothing is shared between threads.
struct Newest {
  size_t frames = 0;
  int64_t tick = -1, publish_ns = 0;  // publish_ns: the server's CLOCK_MONOTONIC (same host only)
  V3 tool{};                          // the tool's centre, m
  // The frame's render model (protocol/local_model.h): x0 (m), F0 (N), the stiffness
  // (N/m, row-major dF_i/dx_j), the valid radius (m) and the stiffness tick.
  palpate::protocol::LocalModel<V3, std::array<double, 9>> model;
};

// The frames' receiver (a capability the server calls). Each frame() must return at once:
// its return frees the flow-control window the next frame needs.
struct Sink final : wire::FrameSink::Server {
  explicit Sink(Newest& newest) : newest(newest) {}
  kj::Promise<void> frame(FrameContext context) override {
    auto f = context.getParams().getFrame();
    auto model = f.getRenderModel();  // renderForce as a function of the device position, (P.0)
    ++newest.frames;
    newest.tick = f.getTick();
    newest.publish_ns = f.getPublishNs();
    newest.tool = vec(f.getIndenterPosition());
    newest.model.origin = vec(model.getOrigin());
    newest.model.force = vec(model.getForce());
    for (unsigned i = 0; i < 9 && i < model.getStiffness().size(); ++i)
      newest.model.stiffness[i] = model.getStiffness()[i];
    newest.model.valid_radius = model.getValidRadius();
    newest.model.stiffness_tick = model.getStiffnessTick();
    return kj::READY_NOW;
  }
  Newest& newest;
};

// The device's path at u = t / duration in [0, 1]: from `start` (the tool at first touch)
// press `depth` down over the first 30 %, slide `slide` along x over the next 40 %, lift back
// over the last 30 %; cosine ramps, so that neither position nor velocity jumps.
V3 device_at(double u, const V3& start, double depth, double slide) {
  auto ramp = [u](double a, double b) {  // 0 before a, 1 after b
    return 0.5 * (1 - std::cos(std::numbers::pi * std::clamp((u - a) / (b - a), 0.0, 1.0)));
  };
  return {start[0] + slide * ramp(0.3, 0.7), start[1], start[2] - depth * (ramp(0.0, 0.3) - ramp(0.7, 1.0))};
}

}  // namespace

int main(int argc, char** argv) {
  palpate::client::ConnectOptions connect;
  std::string scene = "palpation_block", token_file;
  double seconds = 2.0;
  palpate::cli::parse_or_exit(argc, argv, "palpate-example-haptic-client", kUsage, [&](palpate::cli::Arguments& args) {
    if (args.flag() == "--connect") connect.address = args.value();
    else if (args.flag() == "--scene") scene = args.value();
    else if (args.flag() == "--seconds") seconds = args.number(1e-3, 3600);
    else if (args.flag() == "--tls-ca") connect.tls_ca_file = args.value();
    else if (args.flag() == "--access-token-file") token_file = args.value();
    else return false;
    return true;
  });
  Newest newest;        // before the connection: the sink writes it as long as the connection lives
  std::string refused;  // why the server refused a setPosition
  try {
    if (!token_file.empty()) connect.access_token = palpate::client::read_token_file(token_file);
    palpate::client::ServerConnection connection(connect);  // TCP or TLS; authenticates with a token
    kj::WaitScope& ws = connection.wait_scope();
    auto open = connection.server().openSessionRequest();
    auto request = open.initRequest();
    if (!scene.empty()) request.getScene().setName(scene);
    request.initOverrides(1).set(0, "indenter.guide=free");  // a device moves the tool in 3-D
    auto device = request.initDevice();
    device.setMaxStiffness(kMaxStiffness);
    device.setMaxDamping(kMaxDamping);
    device.setMaxForce(kMaxForce);
    auto opened = open.send().wait(ws);  // resolves once the server has built the model
    auto info = opened.getInfo();
    // The owner's capability: only it, or attach() with opened.getControlToken(), commands the
    // session; releasing it ends the session.
    wire::Session::Client session = opened.getSession();
    std::printf("scene %s: %u particles, %.0f Hz, tool R = %g m; coupling %.0f N/m, %.2f N s/m\n",
                info.getSceneName().cStr(), info.getParticleCount(), info.getRateHz(), info.getRadius(),
                info.getCoupling().getStiffness(), info.getCoupling().getDamping());
    auto subscribe = session.subscribeRequest();
    subscribe.setSink(kj::heap<Sink>(newest));
    subscribe.getOptions().setRateHz(0);  // every tick; the scalars and local models only
    auto subscription = subscribe.send().wait(ws).getSubscription();
    for (int waited = 0; newest.frames == 0; ++waited) {  // the path starts where the tool is
      if (waited == 5000) throw std::runtime_error("no frame from the session within 5 s");
      connection.timer().afterDelay(1 * kj::MILLISECONDS).wait(ws);
    }
    const V3 start = {newest.tool[0], newest.tool[1], info.getTouchHeight()};
    std::printf("  t [s] device z [m] render Fx [N] render Fz [N]     tick  frame age\n");
    double peak = 0, next_print = 0;
    long sent = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (auto next = t0;;) {  // the servo loop: one pass per millisecond
      std::this_thread::sleep_until(next += std::chrono::milliseconds(1));
      ws.poll();  // takes the frames and replies that arrived
      if (!refused.empty()) throw std::runtime_error("setPosition: " + refused);
      const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (t >= seconds) break;
      const V3 x = device_at(t / seconds, start, info.getRadius() / 5, info.getRadius());
      auto command = session.setPositionRequest();
      auto position = command.initPosition();
      position.setX(x[0]);
      position.setY(x[1]);
      position.setZ(x[2]);
      command.send().detach([&refused](kj::Exception&& e) { refused = e.getDescription().cStr(); });  // pipelined
      ++sent;
      // The force for the device now: the newest frame's render model at the device's position.
      const V3 f = newest.model.force_at(x, kMaxForce);  // (P.0)
      peak = std::max(peak, std::hypot(f[0], f[1], f[2]));
      if (t >= next_print) {
        timespec now{};
        clock_gettime(CLOCK_MONOTONIC, &now);  // Frame.publishNs's clock
        const double age_ms = (1e9 * now.tv_sec + now.tv_nsec - newest.publish_ns) * 1e-6;
        std::printf("%7.3f %12.6f %13.5f %13.5f %8lld %7.2f ms\n", t, x[2], f[0], f[2],
                    static_cast<long long>(newest.tick), age_ms);
        next_print += std::max(0.1, seconds / 10);
      }
    }
    std::printf("%ld setPosition sent, %zu frames received; peak rendered force %.6g N\n", sent, newest.frames, peak);
    subscription.cancelRequest().send().wait(ws);
    session.closeRequest().send().wait(ws);
    return 0;
  } catch (const kj::Exception& e) {  // the server's refusals name the method, the field and the reason
    std::fprintf(stderr, "palpate-example-haptic-client: %s\n", e.getDescription().cStr());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate-example-haptic-client: %s\n", e.what());
  }
  return 1;
}
