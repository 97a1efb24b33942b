// palpate-fuzz-seeds DIR: writes the seed corpus of server_request_fuzz
// (fuzz/corpus/server_request/): valid requests of every kind, each a kind byte
// and a flat Cap'n Proto message (server_request.h). The seeds are checked in;
// run this again after a schema change.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <string>

#include <capnp/message.h>
#include <capnp/serialize.h>

#include "fuzz/server_request.h"
#include "protocol/palpate.capnp.h"
#include "protocol/scene_wire.h"

namespace {

using namespace palpate;

std::string g_dir;

void write(const std::string& name, fuzz::Kind kind, capnp::MessageBuilder& message) {
  const auto words = capnp::messageToFlatArray(message);
  const auto bytes = words.asBytes();
  std::ofstream out(g_dir + "/" + name, std::ios::binary);
  out.put(static_cast<char>(kind));
  out.write(reinterpret_cast<const char*>(bytes.begin()), static_cast<std::streamsize>(bytes.size()));
}

void open_request(const std::string& name, void (*fill)(wire::OpenRequest::Builder)) {
  capnp::MallocMessageBuilder m;
  fill(m.initRoot<wire::OpenRequest>());
  write(name, fuzz::open_request, m);
}

void inline_scene(const std::string& name, const std::string& json) {
  capnp::MallocMessageBuilder m;
  auto r = m.initRoot<wire::OpenRequest>();
  scene_json_to_wire(json, name, r.getScene().initInlineScene());
  r.setHeadless(true);
  write(name, fuzz::open_request, m);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: palpate-fuzz-seeds DIR\n");
    return 2;
  }
  g_dir = argv[1];
  open_request("open_default", [](wire::OpenRequest::Builder r) {
    r.getScene().setServerDefault();
    auto o = r.initOverrides(1);
    o.set(0, "body.distribution.per_edge=6");
  });
  open_request("open_name_overrides", [](wire::OpenRequest::Builder r) {
    r.getScene().setName("hertz_cube");
    auto o = r.initOverrides(3);
    o.set(0, "body.distribution.per_edge=5");
    o.set(1, "integrator.type=symplectic_euler");
    o.set(2, "verify.forces=[1,2]");
    r.setHeadless(true);
  });
  open_request("open_name_fem", [](wire::OpenRequest::Builder r) {
    r.getScene().setName("hertz_cube_fem");
    auto o = r.initOverrides(1);
    o.set(0, "body.distribution.per_edge=4");
    r.setRateHz(500);
  });
  open_request("open_bad_name", [](wire::OpenRequest::Builder r) { r.getScene().setName("../etc/passwd"); });
  inline_scene("inline_grid", R"({"name": "g", "body": {"box": {"min": [-1, -1, -1], "max": [1, 1, 0]},
      "distribution": {"type": "grid", "per_edge": 6}}, "mls": {"neighbors": 16, "hourglass": 0.1},
      "fixed": ["bottom", "x_min"], "indenter": {"radius": 0.4, "force": 20}, "gravity": [0, 0, -9.81],
      "verify": {"forces": [10, 30]}})");
  inline_scene("inline_jittered", R"({"body": {"distribution": {"type": "jittered_grid", "spacing": 0.5,
      "jitter": 0.2, "seed": 7}}, "mls": {"volumes": "lattice", "support_factor": 1.5},
      "integrator": {"type": "implicit_euler", "dt": 0.01, "damping": 5, "cg_tolerance": 1e-6}})");
  inline_scene("inline_fem", R"({"model": "hex_fem", "hex_fem": {"formulation": "corotational"},
      "body": {"distribution": {"per_edge": 5}}, "material": {"young_modulus": 5e4, "poisson_ratio": 0.45},
      "contact": {"tolerance": 1e-5, "max_iterations": 50}, "fixed": []})");
  inline_scene("inline_node_file", R"({"body": {"distribution": {"type": "node_file",
      "node_file": "hertz_cube.json"}}})");
  {
    capnp::MallocMessageBuilder m;
    m.initRoot<wire::Session::SetForceParams>().setNewtons(10.36);
    write("set_force", fuzz::set_force, m);
  }
  {
    capnp::MallocMessageBuilder m;
    m.initRoot<wire::Session::SetForceParams>().setNewtons(std::numeric_limits<double>::quiet_NaN());
    write("set_force_nan", fuzz::set_force, m);
  }
  {
    capnp::MallocMessageBuilder m;
    auto p = m.initRoot<wire::Session::StepParams>();
    p.setN(100);
    p.initFields().setPositions(true);
    write("step", fuzz::step, m);
  }
  {
    capnp::MallocMessageBuilder m;
    auto p = m.initRoot<wire::Session::SubscribeParams>();
    p.initOptions().setRateHz(60);
    write("subscribe", fuzz::subscribe, m);
  }
  {
    capnp::MallocMessageBuilder m;
    auto p = m.initRoot<wire::Session::SetPositionParams>().initPosition();
    p.setX(0.1);
    p.setY(-0.2);
    p.setZ(0.3);
    write("set_position", fuzz::set_position, m);
  }
  {
    capnp::MallocMessageBuilder m;
    auto f = m.initRoot<wire::Session::SetForceVectorParams>().initForce();
    f.setX(1.0);
    f.setZ(-10.0);
    write("set_force_vector", fuzz::set_force_vector, m);
  }
  {
    capnp::MallocMessageBuilder m;
    auto c = m.initRoot<wire::Session::SetCouplingParams>().initCoupling();
    c.setStiffness(500.0);
    c.setDamping(2.0);
    write("set_coupling", fuzz::set_coupling, m);
  }
  return 0;
}
