// libFuzzer target: what palpate-server does with the bytes of a request.
//
// The input (server_request.h) is a kind byte and a Cap'n Proto message, read
// with capnp::FlatArrayMessageReader under bounded ReaderOptions, then passed
// through the server's own validation (server/requests.h): plan_session, as the
// RPC thread runs it, then resolve_scene, as the session's thread does. A scene
// the server accepts is then built and stepped the way a session thread does
// (server/sim_loop.cpp: build_model, make_state, ticks), with two deviations
// that keep one input fast: at most kMaxParticles particles (the server's
// --max-particles, applied by the same check) and iteration caps of 1000.
//
// The contract: a refusal is a kj::Exception (malformed message or a request the
// server refuses, which goes back to the client); a model build may fail with a
// std::exception (the session reports it as failed). Anything else is a bug.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <exception>

#include <capnp/serialize.h>
#include <kj/array.h>
#include <kj/exception.h>

#include "core/model.h"
#include "core/options.h"
#include "core/state.h"
#include "core/step.h"
#include "fuzz/server_request.h"
#include "protocol/palpate.capnp.h"
#include "server/requests.h"

namespace {

using namespace palpate;
using server::ServerOptions;

constexpr int64_t kMaxParticles = 343;  // 7^3
constexpr int kTicks = 20;

const ServerOptions& options() {
  static const ServerOptions o = [] {
    ServerOptions o;
    o.scene_dir = PALPATE_SOURCE_DIR "/scenes";
    o.default_scene = PALPATE_SOURCE_DIR "/scenes/hertz_cube.json";
    o.max_particles = kMaxParticles;
    return o;
  }();
  return o;
}

// The limit of the server's default scene, as a session of it would apply.
double default_force_limit() {
  static const double limit = server::force_limit(load_scene(options().default_scene));
  return limit;
}

// The session thread's work: build, then ticks at the scene's force and at the limit.
void run_session(Scene scene) {
  scene.contact.max_iterations = std::min(scene.contact.max_iterations, 1000);
  scene.integrator.cg_max_iterations = std::min(scene.integrator.cg_max_iterations, 1000);
  Model model;
  Options opt;
  State state;
  try {
    model = build_model(scene);
    opt = options_of(scene);
    state = make_state(model, opt);
  } catch (const std::exception&) {
    return;  // the session reports "failed" with e.what()
  }
  const double limit = server::force_limit(scene);
  const CouplingOptions coupling{1e3, 10.0};  // setCoupling accepts any finite k, b >= 0
  for (int tick = 0; tick < kTicks; ++tick) {
    if (tick == kTicks / 4) {  // a setPosition the server accepts (a corner of the workspace), stiffly coupled
      state.tool_target = model.tool_workspace_min;
      opt.coupling = coupling;
    }
    if (tick == kTicks / 2) {  // a setForce the server accepts
      state.force_command = press_down(limit);
      opt.coupling = {};
    }
    if (is_fault(step(model, opt, state))) break;          // a blow-up: the server restores a checkpoint
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const uint8_t kind = data[0] % fuzz::kind_count;
  // Word-aligned copy of the message (zero padded to whole words).
  kj::Array<capnp::word> words = kj::heapArray<capnp::word>((size - 1 + sizeof(capnp::word) - 1) / sizeof(capnp::word));
  std::memset(words.begin(), 0, words.size() * sizeof(capnp::word));
  if (size > 1) std::memcpy(words.begin(), data + 1, size - 1);

  capnp::ReaderOptions reader_options;
  reader_options.traversalLimitInWords = 1 << 16;  // 512 KiB: far above any sane request
  reader_options.nestingLimit = 64;
  try {
    capnp::FlatArrayMessageReader message(words, reader_options);
    switch (kind) {
      case fuzz::open_request:
        run_session(server::session_scene(message.getRoot<wire::OpenRequest>(), options()));
        break;
      case fuzz::set_force:
        server::check_force(message.getRoot<wire::Session::SetForceParams>().getNewtons(), default_force_limit());
        break;
      case fuzz::step:
        server::check_step_count(message.getRoot<wire::Session::StepParams>().getN());
        break;
      case fuzz::subscribe:
        server::check_subscriber_rate(message.getRoot<wire::Session::SubscribeParams>().getOptions().getRateHz());
        break;
      case fuzz::set_position:  // the default workspace of the default scene (its box grown by 2 R)
        server::check_position(server::from_wire(message.getRoot<wire::Session::SetPositionParams>().getPosition()),
                               Vec3(-2.0, -2.0, -3.0), Vec3(2.0, 2.0, 1.0));
        break;
      case fuzz::set_force_vector:
        server::check_force_vector(
            server::from_wire(message.getRoot<wire::Session::SetForceVectorParams>().getForce()), default_force_limit());
        break;
      case fuzz::set_coupling: {
        const auto c = message.getRoot<wire::Session::SetCouplingParams>().getCoupling();
        server::check_coupling("setCoupling: coupling", c.getStiffness(), c.getDamping());
        break;
      }
    }
  } catch (const kj::Exception&) {
  }
  return 0;
}
