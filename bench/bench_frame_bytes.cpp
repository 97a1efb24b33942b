// palpate-bench-frame-bytes: bytes per frame for each combination of optional frame fields
// (FrameFields: positions, contacts, displacementMagnitude, vonMises, surfaceOnly), and the
// server-side cost of the derived fields. Usage: kUsage below.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <capnp/ez-rpc.h>
#include <capnp/message.h>
#include <capnp/serialize.h>

#include "cli/arguments.h"
#include "cli/child_process.h"
#include "core/model.h"
#include "core/scene.h"
#include "core/stress.h"
#include "protocol/palpate.capnp.h"

namespace {

using palpate::wire::PalpateServer;

const char* kUsage = R"(usage: palpate-bench-frame-bytes [options]
Starts palpate-server (next to this executable), opens a headless session on each scene,
presses it with --force N for --ticks ticks, then asks step(1) for every combination of
the optional frame fields and prints the size of each frame: the Frame struct serialised
alone as a Cap'n Proto message (segment table included; the RPC call around a streamed
frame adds a few dozen bytes). Then the time the server spends per frame on the derived
fields (|x - X| and von Mises of core/stress.h, on this machine, one thread, the pressed
state, median of 20).
  --scene NAME      a scene of scenes/ by name (repeatable; default hertz_cube and
                    hertz_cube_haptic)
  --force N         the pressing force, N, > 0 (default 53.83)
  --ticks N         ticks pressed before measuring, >= 1 (default 1000)
  --server PATH     the palpate-server executable (default: next to this one)
  --help            print this text and exit
Exit status: 0 when done; 1 when the server does not start or refuses a request (its
message is printed); 2 for a wrong argument.
)";

struct Args {
  std::vector<std::string> scenes;
  double force = 53.83;
  long ticks = 1000;
  std::string server;
};

uint64_t frame_bytes(palpate::wire::Frame::Reader frame) {
  capnp::MallocMessageBuilder message;
  message.setRoot(frame);
  return capnp::computeSerializedSizeInWords(message) * sizeof(capnp::word);
}

double median_ms(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  palpate::cli::parse_or_exit(argc, argv, "palpate-bench-frame-bytes", kUsage, [&](palpate::cli::Arguments& args) {
    const std::string& flag = args.flag();
    if (flag == "--scene") a.scenes.push_back(args.value());
    else if (flag == "--force") {
      a.force = args.number();
      if (!(a.force > 0)) throw std::invalid_argument("--force: must be > 0");
    } else if (flag == "--ticks") a.ticks = static_cast<long>(args.integer(1, 1000000));
    else if (flag == "--server") a.server = args.value();
    else return false;
    return true;
  });
  if (a.scenes.empty()) a.scenes = {"hertz_cube", "hertz_cube_haptic"};

  palpate::cli::ServerProcess server(palpate::cli::program_path(a.server, "palpate-server", argv[0]),
                                     {"--scene-dir", PALPATE_SOURCE_DIR "/scenes", "--log-level", "error"},
                                     {.wait = std::chrono::seconds(120)});
  server.exit_unless_ready("palpate-bench-frame-bytes");
  try {
    capnp::ReaderOptions options;
    options.traversalLimitInWords = 256 * 1024 * 1024;
    capnp::EzRpcClient client(server.address(), 7420, options);
    auto& ws = client.getWaitScope();
    auto bootstrap = client.getMain<PalpateServer>();
    for (const std::string& scene : a.scenes) {
      auto open = bootstrap.openSessionRequest();
      open.initRequest().getScene().setName(scene);
      open.getRequest().setHeadless(true);
      auto opened = open.send().wait(ws);
      auto session = opened.getSession();
      auto info = opened.getInfo();
      const unsigned n = info.getParticleCount(), surface = info.getSurfaceVertices().size();
      auto force = session.setForceRequest();
      force.setNewtons(a.force);
      force.send().wait(ws);
      auto press = session.stepRequest();
      press.setN(static_cast<uint32_t>(a.ticks));
      press.send().wait(ws);

      std::printf("%s: %u particles, %u on the surface (%u triangles), pressed with %.2f N for %ld ticks\n",
                  scene.c_str(), n, surface, info.getSurfaceTriangles().size() / 3, a.force, a.ticks);
      std::printf("%-11s %-5s %-12s %-10s %-8s %12s\n", "positions", "|u|", "von Mises", "contacts", "surface",
                  "bytes/frame");
      std::vector<float> pressed;
      for (int mask = 0; mask < 32; ++mask) {
        const bool p = mask & 1, d = mask & 2, v = mask & 4, c = mask & 8, s = mask & 16;
        if (s && !(p || d || v)) continue;  // surfaceOnly changes nothing without a per-particle list
        auto step = session.stepRequest();
        step.setN(1);
        auto fields = step.initFields();
        fields.setPositions(p);
        fields.setDisplacementMagnitude(d);
        fields.setVonMises(v);
        fields.setContacts(c);
        fields.setSurfaceOnly(s);
        auto response = step.send().wait(ws);
        auto frame = response.getFrame();
        if (p && !s) {
          pressed.clear();
          for (float x : frame.getPositions()) pressed.push_back(x);
        }
        const std::string contacts = c ? "yes (" + std::to_string(frame.getContactNodes().size()) + ")" : "-";
        std::printf("%-11s %-5s %-12s %-10s %-8s %12llu\n", p ? "yes" : "-", d ? "yes" : "-", v ? "yes" : "-",
                    contacts.c_str(), s ? "yes" : "-", static_cast<unsigned long long>(frame_bytes(frame)));
      }
      // The derived fields' cost, as the server computes them (server/frames.cpp: derived_fields).
      const palpate::Model model = palpate::build_model(palpate::load_scene(PALPATE_SOURCE_DIR "/scenes/" + scene + ".json"));
      palpate::Points x(3, model.particle_count);
      for (int i = 0; i < model.particle_count; ++i)
        for (int k = 0; k < 3; ++k) x(k, i) = pressed[3 * static_cast<size_t>(i) + k];
      std::vector<double> dis, vm, out(static_cast<size_t>(model.particle_count));
      for (int r = 0; r < 20; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        for (int i = 0; i < model.particle_count; ++i) out[i] = (x.col(i) - model.rest_position.col(i)).norm();
        const auto t1 = std::chrono::steady_clock::now();
        palpate::von_mises_stress(model, x, out);
        const auto t2 = std::chrono::steady_clock::now();
        dis.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
        vm.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
      }
      double peak = 0;
      for (double s : out) peak = std::max(peak, s);
      std::printf("derived fields per frame: |x - X| %.3f ms, von Mises %.3f ms (largest von Mises %.1f Pa)\n\n",
                  median_ms(dis), median_ms(vm), peak);
    }
  } catch (const kj::Exception& e) {
    std::fprintf(stderr, "palpate-bench-frame-bytes: %s\n", e.getDescription().cStr());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate-bench-frame-bytes: %s\n", e.what());
    return 1;
  }
  return 0;
}
