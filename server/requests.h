#pragma once
// Validation of what clients send (OpenRequest, setForce, step, subscribe).
// Pure functions of the request and the server's options, so that the tests and
// the fuzzers (fuzz/server_request_fuzz.cpp) run exactly what the server runs.
// Every refusal is a kj::Exception (FAILED) whose description goes back to the
// caller as is and names the field: "openSession: request.rateHz: ...".
//
// An OpenRequest is checked in two steps: plan_session() on the RPC thread (cheap
// checks of the message alone, and a copy of it), then resolve_scene() on the
// session's own thread (the scene validator, which looks at files, and the node
// and mesh file rules, which read them).
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
  bool pin_threads = false;             // real-time loops on cores of their own (--pin; SimConfig::cpu)
  int checkpoint_interval = 100;
  int max_sessions = 16;                // concurrent sessions (each owns a thread and a model)
  int64_t max_particles = 200000;       // clouds refused beyond this (memory bound per session)
  // Access control and limits (docs/protocol.md, "Security model"; palpate-server --help).
  int max_sessions_per_connection = 4;  // live sessions one connection may have opened
  int max_subscribers = 16;             // subscribers per session
  int max_wrong_tokens = 10;            // refused tokens (and unknown session ids) per connection
  int wrong_token_delay_ms = 250;       // a refused token's answer waits this long
  std::string access_token;             // --access-token-file's token; empty: no connection-time check
};

// Node and mesh files a client may name: regular files of at most this size.
constexpr std::uintmax_t kMaxNodeFileBytes = 64u << 20;

// An RPC error whose description goes back to the caller as is.
[[noreturn]] void fail(const std::string& message);

// The scene names under dir (<name>.json), sorted.
std::vector<std::string> scene_names(const std::filesystem::path& dir);

// What an OpenRequest asks for, checked and copied out of the RPC message (which
// the session's thread must not read: it is freed when the call ends).
struct OpenPlan {
  SimConfig sim;  // mode, rate and pacing
  enum class SceneKind { server_default, name, inline_scene };
  SceneKind kind = SceneKind::server_default;
  std::string name;         // SceneKind::name: a plain name (letters, digits, '_', '-', '.')
  std::string inline_json;  // SceneKind::inline_scene: the wire scene as scene-file JSON
  SceneOverrides overrides;
};

// RPC thread, no file access: the rate, the kind of scene, a plain scene name, the
// override syntax; an inline scene is converted to JSON. The session count limit is
// the caller's.
OpenPlan plan_session(wire::OpenRequest::Reader request, const ServerOptions& options);

// The session's thread (reads files, up to kMaxNodeFileBytes each): the scene a plan
// names (the server default, <scene_dir>/<name>.json, which must exist, or the inline
// scene through the file validator) with its overrides; node and mesh files only
// inside scene_dir or the default scene's folder, regular and bounded in size; the
// particle limit for lattices, meshes (the node count a mesh header declares) and
// node files (counted up to the limit, without reading further).
Scene resolve_scene(const OpenPlan& plan, const ServerOptions& options);

// Both steps in one (tests, fuzzers, the server's start-up check of its default scene).
Scene session_scene(wire::OpenRequest::Reader request, const ServerOptions& options);

// The largest |F| setForce and setForceVector accept: 100 x the largest verification
// force, or 100 x the Hertz force at d = R / 5 when the scene has no sweep.
double force_limit(const Scene& scene);

// Refuse a NaN, infinite or too large force (N).
void check_force(double newtons, double limit);
void check_force_vector(const Vec3& force, double limit);
// Refuse a device position that is not finite or outside the tool workspace (m).
void check_position(const Vec3& position, const Vec3& workspace_min, const Vec3& workspace_max);
// Refuse a coupling with a negative or non-finite stiffness (N/m) or damping (N s/m).
void check_coupling(const char* where, double stiffness, double damping);
// A wire Vec3.
inline Vec3 from_wire(wire::Vec3::Reader v) { return Vec3(v.getX(), v.getY(), v.getZ()); }
// Refuse a step count outside [1, 1e6].
void check_step_count(uint32_t n);
// Refuse a subscriber rate outside [0, 1e5] Hz (0 = every tick).
void check_subscriber_rate(double rate_hz);
// Refuse a command the session's queue has no room for (`seq` from
// Simulation::enqueue, 0 when full); returns seq.
uint64_t check_queued(const char* method, uint64_t seq);

}  // namespace palpate::server
