#include "server/requests.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <memory>
#include <system_error>
#include <vector>

#include <kj/exception.h>

#include "core/hertz.h"
#include "core/mesh_reader.h"
#include "protocol/scene_wire.h"

namespace palpate::server {

namespace {

namespace fs = std::filesystem;

bool plain_scene_name(const std::string& name) {
  if (name.empty() || name.size() > 200 || name[0] == '.') return false;
  for (char c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) return false;
  return true;
}

// True if `file` (absolute, symlinks resolved) lies below the folder `dir`.
bool inside(const fs::path& file, const fs::path& dir) {
  std::error_code ec;
  const fs::path root = fs::weakly_canonical(dir, ec);
  if (ec || root.empty()) return false;
  const auto [r, f] = std::mismatch(root.begin(), root.end(), file.begin(), file.end());
  return r == root.end() && f != file.end();
}

// A client-named node or mesh file is read by the simulation thread: only a bounded
// regular file inside the server's scene folders (not /dev/zero, a FIFO, or any
// file whose first line the error message would echo). `field` is its JSON pointer.
void check_scene_file(const Scene& scene, const fs::path& file, const std::string& field,
                      const ServerOptions& options) {
  const std::string where = scene.source + ": " + field + ": ";
  std::error_code ec, ec_dir;
  const fs::path real = fs::weakly_canonical(file, ec);
  const fs::path default_dir = fs::absolute(options.default_scene, ec_dir).parent_path();
  if (ec || !(inside(real, options.scene_dir) || (!ec_dir && inside(real, default_dir))))
    fail(where + "'" + file.string() + "' is outside the server's scene folder");
  if (!fs::is_regular_file(real, ec)) fail(where + "'" + file.string() + "' is not a regular file");
  const std::uintmax_t bytes = fs::file_size(real, ec);
  if (ec || bytes > kMaxNodeFileBytes)
    fail(where + "'" + file.string() + "' is larger than " + std::to_string(kMaxNodeFileBytes >> 20) + " MiB");
}

// A mesh cloud (the .msh, or the .node and its .ele) under the same rule, and held
// to the particle limit by the node count its header declares (read before building).
void check_mesh_file(const Scene& scene, const ServerOptions& options) {
  const fs::path& file = scene.distribution.mesh_file;
  const std::string field = "/body/distribution/file";
  check_scene_file(scene, file, field, options);
  if (file.extension() == ".node") check_scene_file(scene, tetgen_element_file(file), field, options);
  int64_t nodes = 0;
  try {
    nodes = declared_mesh_nodes(fs::weakly_canonical(file));
  } catch (const std::exception& e) {
    fail(scene.source + ": " + field + ": " + e.what());
  }
  if (nodes > options.max_particles)
    fail(scene.source + ": " + field + ": the mesh declares " + std::to_string(nodes) +
         " nodes, beyond this server's limit of " + std::to_string(options.max_particles) +
         " particles (palpate-server --max-particles)");
}

// The nodes of a node list (load_node_list's format, core/node_cloud.h: one node a
// line; blank lines and lines whose first character other than ' ', '\t', '\r' is
// '#' are skipped), counted up to stop_after + 1 in constant memory: the file is
// never read past the first node beyond stop_after.
int64_t count_listed_nodes(const fs::path& file, int64_t stop_after, const std::string& where) {
  const std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(file.c_str(), "rb"), &std::fclose);
  if (!f) fail(where + "'" + file.string() + "' cannot be read");
  enum { line_start, skip_line } state = line_start;
  int64_t nodes = 0;
  char buffer[1 << 16];
  for (size_t n; (n = std::fread(buffer, 1, sizeof buffer, f.get())) > 0;) {
    for (size_t k = 0; k < n; ++k) {
      const char c = buffer[k];
      if (c == '\n') state = line_start;
      else if (state == line_start && c != ' ' && c != '\t' && c != '\r') {
        state = skip_line;
        if (c != '#' && ++nodes > stop_after) return nodes;
      }
    }
  }
  if (std::ferror(f.get())) fail(where + "'" + file.string() + "' cannot be read");
  return nodes;
}

// A node-list cloud under the file rule and held to the particle limit.
void check_node_file(const Scene& scene, const ServerOptions& options) {
  const fs::path& file = scene.distribution.node_file;
  const std::string field = "/body/distribution/node_file";
  check_scene_file(scene, file, field, options);
  const std::string where = scene.source + ": " + field + ": ";
  if (count_listed_nodes(fs::weakly_canonical(file), options.max_particles, where) > options.max_particles)
    fail(where + "'" + file.string() + "' lists more than " + std::to_string(options.max_particles) +
         " nodes, this server's particle limit (palpate-server --max-particles)");
}

}  // namespace

void fail(const std::string& message) {
  throw kj::Exception(kj::Exception::Type::FAILED, __FILE__, __LINE__, kj::heapString(message.c_str()));
}

std::vector<std::string> scene_names(const fs::path& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().extension() == ".json") names.push_back(it->path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

double force_limit(const Scene& scene) {
  double f = 0.0;
  for (double v : scene.verify.forces) f = std::max(f, std::abs(v));
  if (f == 0.0)
    f = hertz::force(0.2 * scene.indenter.radius, scene.indenter.radius,
                     hertz::effective_modulus(scene.material.young_modulus, scene.material.poisson_ratio));
  return 100.0 * f;
}

void check_force(double newtons, double limit) {
  if (!std::isfinite(newtons)) fail("setForce: newtons: must be a finite number, got " + std::to_string(newtons));
  if (std::abs(newtons) > limit)
    fail("setForce: newtons: |F| must be at most " + std::to_string(limit) + " N for this scene, got " +
         std::to_string(newtons));
}

namespace {
std::string text(const Vec3& v) {
  char b[96];
  std::snprintf(b, sizeof b, "(%.6g, %.6g, %.6g)", v[0], v[1], v[2]);
  return b;
}
}  // namespace

void check_force_vector(const Vec3& force, double limit) {
  if (!force.allFinite()) fail("setForceVector: force: every component must be a finite number, got " + text(force));
  if (force.norm() > limit)
    fail("setForceVector: force: |F| must be at most " + std::to_string(limit) + " N for this scene, got " +
         std::to_string(force.norm()) + " N");
}

void check_position(const Vec3& position, const Vec3& workspace_min, const Vec3& workspace_max) {
  if (!position.allFinite())
    fail("setPosition: position: every component must be a finite number, got " + text(position));
  for (int a = 0; a < 3; ++a)
    if (position[a] < workspace_min[a] || position[a] > workspace_max[a])
      fail("setPosition: position: " + text(position) + " m is outside the tool workspace " + text(workspace_min) +
           " .. " + text(workspace_max) + " m (SessionInfo.workspaceMin/Max)");
}

void check_coupling(const char* where, double stiffness, double damping) {
  if (!std::isfinite(stiffness) || stiffness < 0.0)
    fail(std::string(where) + ".stiffness: must be a finite number >= 0 (N/m), got " + std::to_string(stiffness));
  if (!std::isfinite(damping) || damping < 0.0)
    fail(std::string(where) + ".damping: must be a finite number >= 0 (N s/m), got " + std::to_string(damping));
}

void check_step_count(uint32_t n) {
  if (n < 1 || n > 1000000) fail("step: n: must be in [1, 1000000], got " + std::to_string(n));
}

void check_subscriber_rate(double rate_hz) {
  if (!std::isfinite(rate_hz) || rate_hz < 0.0 || rate_hz > 100000.0)
    fail("subscribe: options.rateHz: must be in [0, 100000] (0 = every tick), got " + std::to_string(rate_hz));
}

uint64_t check_queued(const char* method, uint64_t seq) {
  if (seq == 0)
    fail(std::string(method) + ": command queue full (" + std::to_string(kMaxQueuedCommands) + " commands pending)");
  return seq;
}

OpenPlan plan_session(wire::OpenRequest::Reader request, const ServerOptions& options) {
  OpenPlan plan;
  plan.sim.headless = request.getHeadless();
  plan.sim.spin_margin_us = options.spin_margin_us;
  plan.sim.try_realtime = options.try_realtime;
  plan.sim.checkpoint_interval = options.checkpoint_interval;
  plan.sim.reference_dir = options.scene_dir / "references";
  const double rate = request.getRateHz();
  if (!(rate == 0.0 || (rate > 0.0 && rate <= 10000.0)))
    fail("openSession: request.rateHz: must be in (0, 10000] (0 = the server's rate), got " + std::to_string(rate));
  plan.sim.rate_hz = rate == 0.0 ? options.rate_hz : rate;
  const double haptic_rate = request.getHapticRateHz();
  if (haptic_rate != 0.0) {
    if (!std::isfinite(haptic_rate) || haptic_rate < plan.sim.rate_hz || haptic_rate > 10000.0)
      fail("openSession: request.hapticRateHz: must be 0 (off) or in [the session's rate (" +
           std::to_string(plan.sim.rate_hz) + " Hz), 10000], got " + std::to_string(haptic_rate));
    if (plan.sim.headless)
      fail("openSession: request.hapticRateHz: multirate rendering needs a real-time session (headless is true)");
    plan.sim.haptic_rate_hz = haptic_rate;
  }

  if (request.hasDevice()) {
    const auto d = request.getDevice();
    const std::pair<const char*, double> limits[] = {
        {"maxStiffness", d.getMaxStiffness()}, {"maxDamping", d.getMaxDamping()}, {"maxForce", d.getMaxForce()}};
    for (const auto& [field, value] : limits)
      if (!std::isfinite(value) || value < 0.0)
        fail(std::string("openSession: request.device.") + field + ": must be a finite number >= 0 (0 = no limit), got " +
             std::to_string(value));
    plan.sim.device = {d.getMaxStiffness(), d.getMaxDamping(), d.getMaxForce()};
  }
  if (request.hasCoupling()) {
    const auto c = request.getCoupling();
    check_coupling("openSession: request.coupling", c.getStiffness(), c.getDamping());
    plan.sim.coupling = {c.getStiffness(), c.getDamping()};
  }

  try {
    for (auto o : request.getOverrides()) plan.overrides.push_back(split_override(o.cStr(), "<rpc overrides>"));
  } catch (const SceneError& e) {
    fail(e.what());
  }
  auto scene = request.getScene();
  switch (scene.which()) {
    case wire::OpenRequest::Scene::SERVER_DEFAULT:
      plan.kind = OpenPlan::SceneKind::server_default;
      break;
    case wire::OpenRequest::Scene::NAME:
      plan.kind = OpenPlan::SceneKind::name;
      plan.name = scene.getName().cStr();
      if (!plain_scene_name(plan.name))
        fail("openSession: request.scene.name: '" + plan.name +
             "' is not a plain scene name (letters, digits, '_', '-', '.'; no path)");
      break;
    case wire::OpenRequest::Scene::INLINE_SCENE:
      plan.kind = OpenPlan::SceneKind::inline_scene;
      try {  // as scene_from_wire does, with the same message
        plan.inline_json = scene_to_json(scene.getInlineScene());
      } catch (const SceneError& e) {
        fail(SceneError("<rpc scene>", e.field(), e.reason()).what());
      } catch (const kj::Exception& e) {
        fail(SceneError("<rpc scene>", "", std::string("cannot encode the scene: ") + e.getDescription().cStr()).what());
      }
      break;
    default:  // a union member from a newer schema
      fail("openSession: request.scene: unknown kind of scene");
  }
  return plan;
}

Scene resolve_scene(const OpenPlan& plan, const ServerOptions& options) {
  Scene scene;
  try {
    switch (plan.kind) {
      case OpenPlan::SceneKind::server_default:
        scene = load_scene(options.default_scene, plan.overrides);
        break;
      case OpenPlan::SceneKind::name: {
        const fs::path file = options.scene_dir / (plan.name + ".json");
        std::error_code ec;
        if (!fs::is_regular_file(file, ec)) {
          std::string known;
          for (const auto& n : scene_names(options.scene_dir)) known += (known.empty() ? "" : ", ") + n;
          fail("openSession: request.scene.name: unknown scene '" + plan.name + "' (known: " + known + ")");
        }
        scene = load_scene(file, plan.overrides);
        break;
      }
      case OpenPlan::SceneKind::inline_scene:
        scene = parse_scene(plan.inline_json, "<rpc scene>", options.scene_dir, plan.overrides);
        break;
    }
  } catch (const SceneError& e) {
    fail(e.what());
  }

  // Bounded memory: refuse clouds beyond the server's particle limit before building.
  if (const auto& d = scene.distribution; d.type == DistributionType::node_file) {
    check_node_file(scene, options);
  } else if (d.type == DistributionType::mesh) {
    check_mesh_file(scene, options);
  } else {
    double count = 1.0;
    for (int a = 0; a < 3; ++a) {
      const double edge = scene.box.max[a] - scene.box.min[a];
      count *= d.spacing > 0.0 ? std::round(edge / d.spacing) + 1.0 : d.per_edge;
    }
    if (count > static_cast<double>(options.max_particles)) {
      char text[64];  // count may be far beyond any integer type (a tiny spacing)
      std::snprintf(text, sizeof text, "%.0f", count);
      fail(scene.source + ": /body/distribution: " + text +
           " particles exceed this server's limit of " + std::to_string(options.max_particles) +
           " (palpate-server --max-particles)");
    }
  }
  return scene;
}

Scene session_scene(wire::OpenRequest::Reader request, const ServerOptions& options) {
  return resolve_scene(plan_session(request, options), options);
}

}  // namespace palpate::server
