#pragma once
// Validation of what clients send (OpenRequest, setForce, step, subscribe).
// Pure functions of the request and the server's options, so that the tests and
// the fuzzers (fuzz/server_request_fuzz.cpp) run exactly what the server runs.
// Every refusal is a kj::Exception (FAILED) whose description goes back to the
// caller as is and names the field: "openSession: request.rateHz: ...".
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/scene.h"
#include "protocol/palpate.capnp.h"
#include "server/sim_loop.h"

namespace palpate::server {

struct ServerOptions {
  std::filesystem::path scene_dir;      // name-based opens: <scene_dir>/<name>.json
  std::filesystem::path default_scene;  // opens without a scene
  double rate_hz = 1000.0;
  double spin_margin_us = 200.0;
  bool try_realtime = true;
  int checkpoint_interval = 100;
  int max_sessions = 16;                // concurrent sessions (each owns a thread and a model)
  double max_particles = 200000;        // lattice size refused beyond this (memory bound per session)
};

// Node and mesh files a client may name: regular files of at most this size.
constexpr std::uintmax_t kMaxNodeFileBytes = 64u << 20;

// An RPC error whose description goes back to the caller as is.
[[noreturn]] void fail(const std::string& message);

// The scene names under dir (<name>.json), sorted.
std::vector<std::string> scene_names(const std::filesystem::path& dir);

// The session an OpenRequest asks for: rate, scene (server default, a plain name
// under scene_dir, or an inline Scene through the file validator), overrides,
// the particle limit for lattices and meshes (the node count a mesh header declares),
// and node and mesh files only inside scene_dir or the default scene's folder. The
// session count limit is the caller's.
SimConfig session_config(wire::OpenRequest::Reader request, const ServerOptions& options);

// The largest |F| setForce accepts: 100 x the largest verification force, or
// 100 x the Hertz force at 0.1 m depth when the scene has no sweep.
double force_limit(const Scene& scene);

// Refuse a NaN, infinite or too large force (N).
void check_force(double newtons, double limit);
// Refuse a step count outside [1, 1e6].
void check_step_count(uint32_t n);
// Refuse a subscriber rate outside [0, 1e5] Hz (0 = every tick).
void check_subscriber_rate(double rate_hz);

}  // namespace palpate::server
