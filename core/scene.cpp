// Scene files: JSON -> plain structs, validated field by field (docs/scene-format.md).
//
// A Reader pairs a JSON value with its JSON pointer, so every accessor reports the
// path of the value it rejects. Sections are read in document order and the first
// error is thrown as a SceneError(source, pointer, reason).
#include "core/scene.h"

#include "core/hertz.h"
#include "core/mesh_reader.h"
#include "core/node_cloud.h"
#include "core/resolution.h"
#include "core/thread_pool.h"

#include <algorithm>
#include <charconv>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <span>
#include <string_view>
#include <system_error>

#include <nlohmann/json.hpp>

namespace palpate {

namespace fs = std::filesystem;

SceneError::SceneError(const std::string& source, const std::string& field, const std::string& reason)
    : std::runtime_error(source + ": " + (field.empty() ? std::string() : field + ": ") + reason),
      source_(source),
      field_(field),
      reason_(reason) {}

namespace {

using json = nlohmann::json;

constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------
// Names of enumerated values: the single list used by parsing, messages and to_string.

template <class T>
struct Named {
  std::string_view name;
  T value;
};

constexpr std::string_view kModels[] = {"mls", "hex_fem"};

constexpr Named<HexFormulation> kHexFormulations[] = {
    {"linear", HexFormulation::linear},
    {"corotational", HexFormulation::corotational},
    {"neo_hookean", HexFormulation::neo_hookean},
};
constexpr Named<HexVolumetricIntegration> kHexVolumetricIntegrations[] = {
    {"full", HexVolumetricIntegration::full},
    {"reduced", HexVolumetricIntegration::reduced},
};

constexpr Named<SupportRule> kSupportRules[] = {
    {"mean_distance", SupportRule::mean_distance},
    {"kth_distance", SupportRule::kth_distance},
};
constexpr Named<IntegrationRule> kIntegrationRules[] = {
    {"nodal", IntegrationRule::nodal},
    {"consistent", IntegrationRule::consistent},
};

constexpr Named<MaterialLaw> kMaterialLaws[] = {
    {"stvk", MaterialLaw::stvk}, {"corotational", MaterialLaw::corotational}, {"linear", MaterialLaw::linear},
    {"neo_hookean", MaterialLaw::neo_hookean}};
constexpr Named<DistributionType> kDistributions[] = {
    {"grid", DistributionType::grid},
    {"jittered_grid", DistributionType::jittered_grid},
    {"graded_grid", DistributionType::graded_grid},
    {"node_file", DistributionType::node_file},
    {"mesh", DistributionType::mesh},
};

constexpr Named<VolumeRule> kVolumeRules[] = {
    {"kernel", VolumeRule::kernel},
    {"lattice", VolumeRule::lattice},
    {"mesh", VolumeRule::mesh},
};

constexpr Named<ToolGuide> kToolGuides[] = {
    {"vertical", ToolGuide::vertical},
    {"free", ToolGuide::free},
};

constexpr Named<IntegratorType> kIntegrators[] = {
    {"rk4", IntegratorType::rk4},
    {"symplectic_euler", IntegratorType::symplectic_euler},
    {"implicit_euler", IntegratorType::implicit_euler},
};

constexpr Named<uint32_t> kFaces[] = {
    {"bottom", face_bottom}, {"top", face_top},     {"x_min", face_x_min}, {"x_max", face_x_max},
    {"y_min", face_y_min},   {"y_max", face_y_max}, {"sides", faces_sides},
};

// ---------------------------------------------------------------------------
// The keys of every object of a scene file, in document order: the one list the
// reader checks keys against and scene_field_paths() reports.

constexpr std::string_view kSceneKeys[] = {"name",     "model",   "body",       "mls",     "hex_fem",
                                           "material", "fixed",   "indenter",   "contact", "integrator",
                                           "gravity",  "verify",  "health"};
constexpr std::string_view kBodyKeys[] = {"box", "distribution"};
constexpr std::string_view kBoxKeys[] = {"min", "max"};
constexpr std::string_view kDistributionKeys[] = {"type",          "per_edge", "spacing",   "jitter", "seed",
                                                  "first_spacing", "focus",    "node_file", "file",
                                                  "refine"};
constexpr std::string_view kRefineKeys[] = {"size", "growth", "max_size"};
constexpr std::string_view kMlsKeys[] = {"neighbors",   "max_neighbors", "support_factor", "support_rule",
                                         "integration", "volumes",       "hourglass",      "regularization"};
constexpr std::string_view kHexFemKeys[] = {"formulation", "volumetric_integration"};
constexpr std::string_view kMaterialKeys[] = {"young_modulus",    "poisson_ratio", "density",
                                              "volume_stiffness", "law",           "inclusions"};
// Each element of material.inclusions (a leaf field of scene_field_paths: an array of these).
constexpr std::string_view kInclusionKeys[] = {"sphere", "box", "group", "young_modulus", "poisson_ratio", "density"};
constexpr std::string_view kInclusionShapes[] = {"sphere", "box", "group"};
constexpr std::string_view kSphereKeys[] = {"center", "radius"};
constexpr std::string_view kInclusionBoxKeys[] = {"min", "max"};
// An object element of `fixed` (docs/scene-format.md, "fixed"); its sphere and box take
// kSphereKeys and kInclusionBoxKeys as an inclusion's do.
constexpr std::string_view kFixedRegionKeys[] = {"group", "plane", "box", "sphere"};
constexpr std::string_view kFixedPlaneKeys[] = {"point", "normal", "tolerance"};
constexpr std::string_view kIndenterKeys[] = {"radius", "mass", "position", "force", "workspace_min", "workspace_max",
                                              "guide"};
constexpr std::string_view kContactKeys[] = {"tolerance", "max_iterations"};
constexpr std::string_view kIntegratorKeys[] = {"type",         "dt", "damping", "cg_tolerance", "cg_max_iterations",
                                                "allow_unstable_dt", "threads"};
constexpr std::string_view kVerifyKeys[] = {"forces", "rest"};
constexpr std::string_view kRestKeys[] = {"velocity_tolerance", "force_tolerance", "window", "max_time"};
constexpr std::string_view kHealthKeys[] = {"enabled", "energy_factor", "max_indenter_speed", "max_penetration",
                                            "inversion_sweep_ticks"};

// The objects of a scene file by JSON pointer; every other key is a field.
struct Section {
  std::string_view pointer;
  std::span<const std::string_view> keys;
};
constexpr Section kSections[] = {
    {"", kSceneKeys},           {"/body", kBodyKeys},         {"/body/box", kBoxKeys},
    {"/body/distribution", kDistributionKeys},                {"/body/distribution/refine", kRefineKeys},
    {"/mls", kMlsKeys},
    {"/hex_fem", kHexFemKeys},  {"/material", kMaterialKeys}, {"/indenter", kIndenterKeys},
    {"/contact", kContactKeys}, {"/integrator", kIntegratorKeys},
    {"/verify", kVerifyKeys},   {"/verify/rest", kRestKeys},  {"/health", kHealthKeys},
};

const Section* section_at(std::string_view pointer) {
  for (const Section& s : kSections)
    if (s.pointer == pointer) return &s;
  return nullptr;
}

void add_field_paths(const Section& section, std::vector<std::string>& out) {
  for (std::string_view key : section.keys) {
    const std::string path = std::string(section.pointer) + "/" + std::string(key);
    if (const Section* child = section_at(path)) add_field_paths(*child, out);
    else out.push_back(path);
  }
}

std::string_view name_of(std::string_view s) { return s; }
template <class T>
std::string_view name_of(const Named<T>& n) {
  return n.name;
}

template <class List>
std::string join_names(const List& list) {
  std::string out;
  for (const auto& item : list) {
    if (!out.empty()) out += ", ";
    out += name_of(item);
  }
  return out;
}

template <class T, std::size_t N>
const char* name_for(const Named<T> (&names)[N], T value) {
  for (const auto& n : names)
    if (n.value == value) return n.name.data();  // the names are NUL-terminated literals
  return "?";
}

// ---------------------------------------------------------------------------
// Formatting for messages.

// Shortest text that reads back as x, with a compact exponent: 0.7, 1000, 1e12, 1e-6.
std::string fmt(double x) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, x);
  std::string s(buf, res.ptr);
  if (const auto e = s.find('e'); e != std::string::npos) {
    std::size_t digits = e + 1;
    const bool negative = s[digits] == '-';
    if (s[digits] == '+' || s[digits] == '-') ++digits;
    while (digits + 1 < s.size() && s[digits] == '0') ++digits;
    s = s.substr(0, e + 1) + (negative ? "-" : "") + s.substr(digits);
  }
  return s;
}

// "string \"NaN\"", "number 3.5", "array of 2 elements", "object", "null".
std::string describe(const json& v) {
  std::string s = v.type_name();
  if (v.is_array()) return s + " of " + std::to_string(v.size()) + (v.size() == 1 ? " element" : " elements");
  if (v.is_primitive() && !v.is_null()) {
    std::string text = v.dump(-1, ' ', false, json::error_handler_t::replace);  // a bare override may be bad UTF-8
    if (text.size() > 40) text = text.substr(0, 37) + "...";
    s += " " + text;
  }
  return s;
}

// One reference token of a JSON pointer (RFC 6901: '~' -> "~0", '/' -> "~1").
std::string pointer_token(std::string_view key) {
  std::string out;
  for (char c : key) {
    if (c == '~') out += "~0";
    else if (c == '/') out += "~1";
    else out += c;
  }
  return out;
}

// True if `path` is `root` or lies below it.
bool within(const std::string& path, const std::string& root) {
  return path.compare(0, root.size(), root) == 0 && (path.size() == root.size() || path[root.size()] == '/');
}

// ---------------------------------------------------------------------------
// Number ranges, with their text for messages.

struct Range {
  double lo, hi;
  bool lo_open, hi_open;

  bool contains(double x) const {
    return (lo_open ? x > lo : x >= lo) && (hi_open ? x < hi : x <= hi);
  }
  std::string text() const {
    if (hi == kInf) return (lo_open ? "> " : ">= ") + fmt(lo);
    return std::string("in ") + (lo_open ? "(" : "[") + fmt(lo) + ", " + fmt(hi) + (hi_open ? ")" : "]");
  }
};
constexpr Range closed(double lo, double hi) { return {lo, hi, false, false}; }
constexpr Range open(double lo, double hi) { return {lo, hi, true, true}; }
constexpr Range open_closed(double lo, double hi) { return {lo, hi, true, false}; }
constexpr Range closed_open(double lo, double hi) { return {lo, hi, false, true}; }
constexpr Range at_least(double lo) { return {lo, kInf, false, true}; }
constexpr Range positive() { return {0.0, kInf, true, true}; }

// ---------------------------------------------------------------------------
// Where the scene text came from: the source name, and which pointers the
// overrides set, so that an error in an overridden value names the override.

struct Origin {
  std::string source;
  std::vector<std::pair<std::string, std::string>> overrides;  // (JSON pointer, "key=value")
  SceneFiles files = SceneFiles::required;  // whether the files a scene names must exist

  std::string source_for(const std::string& field) const {
    if (!field.empty())
      for (auto it = overrides.rbegin(); it != overrides.rend(); ++it)  // the last override wins
        if (within(field, it->first) || within(it->first, field)) return override_source(source, it->second);
    return source;
  }
  static std::string override_source(const std::string& source, const std::string& assignment) {
    return source + " (override " + assignment + ")";
  }
};

// ---------------------------------------------------------------------------
// A JSON value (possibly absent) and its JSON pointer. Every accessor that finds
// the value unacceptable throws a SceneError naming that pointer. The get()
// accessors leave their output (the struct default) untouched when the value is absent.

class Reader {
 public:
  Reader(const json* value, std::string path, const Origin& origin)
      : value_(value), path_(std::move(path)), origin_(&origin) {}

  bool present() const { return value_ != nullptr; }
  bool is_object() const { return value_ && value_->is_object(); }
  bool files_required() const { return origin_->files == SceneFiles::required; }

  [[noreturn]] void fail(const std::string& reason) const {
    throw SceneError(origin_->source_for(path_), path_, reason);
  }

  // A member of this object; absent when this is absent or has no such key.
  Reader operator[](std::string_view key) const {
    const json* child = nullptr;
    if (value_ && value_->is_object())
      if (const auto it = value_->find(key); it != value_->end()) child = &*it;
    return {child, path_ + "/" + pointer_token(key), *origin_};
  }

  // Requires an object whose keys are all in `known`.
  void object(std::span<const std::string_view> known) const {
    if (!present()) return;
    if (!value_->is_object()) fail("expected an object, got " + describe(*value_));
    for (const auto& item : value_->items()) {
      bool ok = false;
      for (std::string_view k : known) ok = ok || item.key() == k;
      if (!ok) (*this)[item.key()].fail("unknown field (known: " + join_names(known) + ")");
    }
  }

  // Requires an array; returns its elements. `what` describes the expected array.
  std::vector<Reader> elements(std::string_view what) const {
    if (!value_->is_array()) fail("expected " + std::string(what) + ", got " + describe(*value_));
    std::vector<Reader> out;
    for (std::size_t i = 0; i < value_->size(); ++i)
      out.emplace_back(&(*value_)[i], path_ + "/" + std::to_string(i), *origin_);
    return out;
  }

  // Requires a finite number.
  double number() const {
    if (!value_->is_number()) fail("expected a number, got " + describe(*value_));
    const double x = value_->get<double>();
    if (!std::isfinite(x)) fail("must be a finite number, got " + fmt(x));
    return x;
  }

  void get(double& out, Range range) const {
    if (!present()) return;
    const double x = number();
    if (!range.contains(x)) fail("must be a number " + range.text() + ", got " + fmt(x));
    out = x;
  }

  void get(int& out, int lo, int hi) const {
    if (!present()) return;
    const double x = number();
    if (x != std::floor(x) || x < lo || x > hi)
      fail("must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + fmt(x));
    out = static_cast<int>(x);
  }

  void get(uint64_t& out) const {
    if (!present()) return;
    if (value_->is_number_unsigned()) {
      out = value_->get<uint64_t>();
      return;
    }
    const double x = number();
    if (x != std::floor(x) || x < 0.0 || x >= 18446744073709551616.0)  // 2^64
      fail("must be a non-negative integer, got " + fmt(x));
    out = static_cast<uint64_t>(x);
  }

  void get(bool& out) const {
    if (!present()) return;
    if (!value_->is_boolean()) fail("expected true or false, got " + describe(*value_));
    out = value_->get<bool>();
  }

  // A non-empty string.
  void get(std::string& out) const {
    if (!present()) return;
    if (!value_->is_string()) fail("expected a string, got " + describe(*value_));
    const auto& s = value_->get_ref<const std::string&>();
    if (s.empty()) fail("must be a non-empty string");
    out = s;
  }

  // A 3-vector of finite numbers.
  void get(Vec3& out) const {
    if (!present()) return;
    if (!value_->is_array() || value_->size() != 3) fail("expected an array of 3 numbers, got " + describe(*value_));
    Vec3 v;
    const auto e = elements("an array of 3 numbers");
    for (int i = 0; i < 3; ++i) v[i] = e[i].number();  // in order: the first bad element is reported
    out = v;
  }

  // One of `names` (the entries' names); nullptr when absent. `what` names the kind for messages.
  template <class List>
  auto pick(std::string_view what, const List& names) const -> decltype(std::data(names)) {
    if (!present()) return nullptr;
    if (!value_->is_string()) fail("expected a string, got " + describe(*value_));
    const auto& s = value_->get_ref<const std::string&>();
    for (const auto& n : names)
      if (name_of(n) == s) return &n;
    fail("unknown " + std::string(what) + " '" + s + "' (known: " + join_names(names) + ")");
  }

  template <class T, std::size_t N>
  void get(T& out, std::string_view what, const Named<T> (&names)[N]) const {
    if (const auto* n = pick(what, names)) out = n->value;
  }

 private:
  const json* value_;  // nullptr: absent
  std::string path_;
  const Origin* origin_;
};

// ---------------------------------------------------------------------------
// Sections, in document order.

void read_box(const Reader& r, BoxSpec& box) {
  r.object(kBoxKeys);
  r["min"].get(box.min);
  r["max"].get(box.max);
  constexpr char kAxis[] = "xyz";
  for (int a = 0; a < 3; ++a) {
    const double edge = box.max[a] - box.min[a];
    if (!(edge > 0.0))
      r.fail(std::string("max must exceed min in every component (") + kAxis[a] + ": max " + fmt(box.max[a]) +
             " <= min " + fmt(box.min[a]) + ")");
    if (edge > 1000.0)
      r.fail(std::string("every edge must be at most 1000 m (") + kAxis[a] + ": " + fmt(edge) + " m)");
  }
}

// A file named in the scene: relative paths are resolved against base_dir; absolute, normalised.
fs::path resolve_file(const std::string& name, const fs::path& base_dir) {
  fs::path p = name;
  if (p.is_relative()) p = base_dir / p;
  std::error_code ec;
  const fs::path abs = fs::absolute(p, ec);
  return (ec ? p : abs).lexically_normal();
}

// Requires `file` (the scene's text `name`, resolved) to exist and not be a folder.
void require_file(const Reader& r, const std::string& what, const std::string& name, const fs::path& file) {
  if (!r.files_required()) return;
  std::error_code ec;
  const auto status = fs::status(file, ec);
  if (!fs::exists(status)) r.fail(what + " '" + name + "' not found (resolved to " + file.string() + ")");
  if (fs::is_directory(status)) r.fail(what + " '" + name + "' is a directory (resolved to " + file.string() + ")");
}

// read_distribution's mark for a refine object without a size (never left in a Scene).
constexpr double kDeriveRefineSize = -1.0;

void read_distribution(const Reader& r, const BoxSpec& box, const fs::path& base_dir, DistributionSpec& d) {
  r.object(kDistributionKeys);
  r["type"].get(d.type, "distribution type", kDistributions);
  r["per_edge"].get(d.per_edge, 2, 200);
  r["spacing"].get(d.spacing, at_least(0.0));
  r["jitter"].get(d.jitter, closed_open(0.0, 0.5));
  r["seed"].get(d.seed);
  d.first_spacing = 0.0;  // left out or 0: derived from the scene (read_scene, core/resolution.h)
  r["first_spacing"].get(d.first_spacing, at_least(0.0));
  if (r["focus"].present()) {
    r["focus"].get(d.focus);
    d.focus_given = true;
  }
  std::string node_file, mesh_file;
  r["node_file"].get(node_file);
  r["file"].get(mesh_file);

  const bool lattice = d.type != DistributionType::node_file && d.type != DistributionType::mesh;
  if (d.spacing > 0.0 && lattice) {
    constexpr char kAxis[] = "xyz";
    for (int a = 0; a < 3; ++a) {
      const double edge = box.max[a] - box.min[a];
      const double nodes = std::round(edge / d.spacing) + 1.0;
      if (nodes < 2.0 || nodes > 200.0)
        r["spacing"].fail("gives " + (nodes > 1e6 ? std::string("over a million") : fmt(nodes)) + " nodes along " + kAxis[a] + " (edge " + fmt(edge) +
                          " m); round(edge / spacing) + 1 must be in [2, 200]");
    }
  }

  if (const Reader refine = r["refine"]; refine.present()) {
    refine.object(kRefineKeys);
    d.refine.size = kDeriveRefineSize;  // read_scene derives it when left out (a mesh only)
    if (refine["size"].present()) refine["size"].get(d.refine.size, open_closed(0.0, 1e3));
    refine["growth"].get(d.refine.growth, open_closed(1.0, 10.0));
    refine["max_size"].get(d.refine.max_size, closed(0.0, 1e3));
    if (d.refine.max_size > 0 && d.refine.max_size <= d.refine.size)
      refine["max_size"].fail("must exceed size (else nothing is refined), or be 0 (no limit)");
  }
  if (!node_file.empty()) d.node_file = resolve_file(node_file, base_dir);
  if (!mesh_file.empty()) d.mesh_file = resolve_file(mesh_file, base_dir);
  if (d.type == DistributionType::node_file) {
    const Reader f = r["node_file"];
    if (node_file.empty()) f.fail("required when type is 'node_file' (a text file of \"x y z\" lines)");
    require_file(f, "node file", node_file, d.node_file);
  }
  if (d.type == DistributionType::mesh) {
    const Reader f = r["file"];
    if (mesh_file.empty())
      f.fail("required when type is 'mesh' (a tetrahedral mesh: .msh of gmsh, or .node with its .ele of TetGen)");
    if (!known_mesh_extension(d.mesh_file))
      f.fail("unknown mesh format '" + d.mesh_file.extension().string() + "' of '" + mesh_file +
             "' (known: .msh, gmsh 4.1 or 2.2 ASCII; .node with its sibling .ele, TetGen)");
    require_file(f, "mesh file", mesh_file, d.mesh_file);
    if (d.mesh_file.extension() == ".node") {
      const fs::path ele = tetgen_element_file(d.mesh_file);
      require_file(f, "the TetGen element file of", mesh_file, ele);
    }
  }
}

// A graded lattice must fit its box: the focus inside, the first spacing shorter than
// every side it grades.
void check_graded_grid(const Reader& r, const Scene& s) {
  const Vec3 focus = graded_focus(s);
  constexpr char kAxis[] = "xyz";
  for (int a = 0; a < 3; ++a)
    if (!(focus[a] >= s.box.min[a] && focus[a] <= s.box.max[a]))
      r["focus"].fail(std::string("the focus must lie in the box (") + kAxis[a] + " = " + fmt(focus[a]) +
                      " is outside [" + fmt(s.box.min[a]) + ", " + fmt(s.box.max[a]) + "])");
  const Eigen::Vector3i per_axis = s.distribution.spacing > 0 ? nodes_per_axis(s.box, s.distribution.spacing)
                                                              : Eigen::Vector3i::Constant(s.distribution.per_edge);
  for (int a = 0; a < 3; ++a) {
    try {
      graded_axis(s.box.min[a], s.box.max[a], focus[a], per_axis[a], s.distribution.first_spacing);
    } catch (const std::invalid_argument& e) {
      r["first_spacing"].fail(std::string(e.what()).substr(std::string("graded lattice: ").size()) + " along " +
                              kAxis[a]);
    }
  }
}

void read_body(const Reader& r, const fs::path& base_dir, Scene& s) {
  r.object(kBodyKeys);
  read_box(r["box"], s.box);
  read_distribution(r["distribution"], s.box, base_dir, s.distribution);
  s.box_given = r["box"].present() || s.distribution.type != DistributionType::mesh;
}

void read_mls(const Reader& r, DistributionType distribution, MlsSpec& m) {
  r.object(kMlsKeys);
  r["neighbors"].get(m.neighbors, 4, 64);
  r["max_neighbors"].get(m.max_neighbors, 0, 128);
  if (m.max_neighbors != 0 && m.max_neighbors < m.neighbors)
    r["max_neighbors"].fail("must be 0 (off) or at least neighbors (" + std::to_string(m.neighbors) + "), got " +
                            std::to_string(m.max_neighbors));
  r["support_factor"].get(m.support_factor, open_closed(0.0, 10.0));
  r["support_rule"].get(m.support_rule, "support rule", kSupportRules);
  r["integration"].get(m.integration, "integration rule", kIntegrationRules);
  r["volumes"].get(m.volumes, "volume rule", kVolumeRules);
  r["hourglass"].get(m.hourglass, closed(0.0, 100.0));
  r["regularization"].get(m.regularization, closed_open(0.0, 1.0));
  if (m.volumes == VolumeRule::lattice && distribution == DistributionType::node_file)
    r["volumes"].fail(
        "'lattice' needs a lattice: a node_file cloud has no lattice cell volumes; use 'kernel' "
        "(or a grid distribution)");
  // A mesh cloud's volumes are its tetrahedra's, and only a mesh has tetrahedra. Required
  // rather than defaulted: the wire omits the default ('kernel'), so a default that
  // depended on the distribution could not be told from an explicit 'kernel'.
  if (distribution == DistributionType::mesh && m.volumes != VolumeRule::mesh)
    r["volumes"].fail(std::string("a 'mesh' distribution takes its volumes from the tetrahedra: set \"volumes\": \"mesh\" (got '") +
                      (m.volumes == VolumeRule::kernel ? "kernel" : "lattice") +
                      (r["volumes"].present() ? "')" : "', the default)"));
  if (m.volumes == VolumeRule::mesh && distribution != DistributionType::mesh)
    r["volumes"].fail("'mesh' volumes need a 'mesh' distribution (tetrahedra); use 'kernel' or 'lattice'");
}

void read_hex_fem(const Reader& r, HexFemSpec& h) {
  r.object(kHexFemKeys);
  r["formulation"].get(h.formulation, "formulation", kHexFormulations);
  r["volumetric_integration"].get(h.volumetric_integration, "volumetric integration", kHexVolumetricIntegrations);
  if (h.formulation == HexFormulation::neo_hookean && h.volumetric_integration == HexVolumetricIntegration::reduced)
    r["volumetric_integration"].fail(
        "the neo_hookean formulation integrates fully (2x2x2 Gauss points); 'reduced' applies to linear and "
        "corotational");
}

// {"center": [x, y, z], "radius": r}: a ball, m (an inclusion's, a fixed region's).
void read_sphere(const Reader& r, Vec3& center, double& radius) {
  r.object(kSphereKeys);
  if (!r["center"].present()) r["center"].fail("required: the sphere's centre [x, y, z] in m");
  if (!r["radius"].present()) r["radius"].fail("required: the sphere's radius in m");
  r["center"].get(center);
  r["radius"].get(radius, open_closed(0.0, 1e3));
}

// {"min": [x, y, z], "max": [x, y, z]}: a box, m. `solid`: max > min in every component (a
// region of material has volume); else max >= min (a fixed slab may be flat).
void read_box_corners(const Reader& r, Vec3& min, Vec3& max, bool solid) {
  r.object(kInclusionBoxKeys);
  if (!r["min"].present()) r["min"].fail("required: the box's lower corner [x, y, z] in m");
  if (!r["max"].present()) r["max"].fail("required: the box's upper corner [x, y, z] in m");
  r["min"].get(min);
  r["max"].get(max);
  constexpr char kAxis[] = "xyz";
  for (int a = 0; a < 3; ++a)
    if (solid ? !(max[a] > min[a]) : !(max[a] >= min[a]))
      r["max"].fail(std::string(solid ? "must exceed min in every component (" : "must be at least min in every component (") +
                    kAxis[a] + ": " + fmt(max[a]) + (solid ? " <= " : " < ") + fmt(min[a]) + ")");
}

// material.inclusions: [{"sphere": {...} | "box": {...}, "young_modulus", "poisson_ratio", "density"?}, ...],
// the constants in the matrix material's ranges; density defaults to the matrix's.
void read_inclusions(const Reader& r, MaterialSpec& m) {
  if (!r.present()) return;
  m.inclusions.clear();
  for (const Reader& e : r.elements("an array of inclusions")) {
    e.object(kInclusionKeys);
    int shapes = 0;
    for (std::string_view k : kInclusionShapes) shapes += e[k].present();
    if (!e.present() || shapes != 1)
      e.fail("an inclusion needs exactly one shape key (one of: " + join_names(kInclusionShapes) + ")");
    InclusionSpec inc;
    inc.density = m.density;
    if (const Reader group = e["group"]; group.present()) {
      inc.shape = InclusionShape::group;
      group.get(inc.group);
      if (inc.group.empty()) group.fail("the name of a physical volume group of the mesh, not empty");
    } else if (const Reader sphere = e["sphere"]; sphere.present()) {
      inc.shape = InclusionShape::sphere;
      read_sphere(sphere, inc.center, inc.radius);
    } else {
      inc.shape = InclusionShape::box;
      read_box_corners(e["box"], inc.min, inc.max, /*solid=*/true);
    }
    if (!e["young_modulus"].present()) e["young_modulus"].fail("required: the inclusion's Young's modulus in Pa");
    if (!e["poisson_ratio"].present()) e["poisson_ratio"].fail("required: the inclusion's Poisson ratio");
    e["young_modulus"].get(inc.young_modulus, open_closed(0.0, 1e12));
    e["poisson_ratio"].get(inc.poisson_ratio, open(-1.0, 0.5));
    e["density"].get(inc.density, open_closed(0.0, 1e5));
    m.inclusions.push_back(inc);
  }
}

void read_material(const Reader& r, MaterialSpec& m) {
  r.object(kMaterialKeys);
  r["young_modulus"].get(m.young_modulus, open_closed(0.0, 1e12));
  r["poisson_ratio"].get(m.poisson_ratio, open(-1.0, 0.5));
  r["density"].get(m.density, open_closed(0.0, 1e5));
  r["volume_stiffness"].get(m.volume_stiffness, closed(0.0, 1e12));
  r["law"].get(m.law, "material law", kMaterialLaws);
  read_inclusions(r["inclusions"], m);
}

// One object element of `fixed`: exactly one of group / plane / box / sphere.
FixedRegion read_fixed_region(const Reader& e, const std::string& field) {
  e.object(kFixedRegionKeys);
  int shapes = 0;
  for (std::string_view k : kFixedRegionKeys) shapes += e[k].present();
  if (shapes != 1)
    e.fail("a fixed region needs exactly one of the keys " + join_names(kFixedRegionKeys) +
           " (or a face name string)");
  FixedRegion region;
  region.field = field;
  auto required = [](const Reader& r, const char* what) {
    if (!r.present()) r.fail(std::string("required: ") + what);
  };
  if (const Reader g = e["group"]; g.present()) {
    region.kind = FixedRegionKind::group;
    g.get(region.group);
    if (region.group.empty()) g.fail("the name of a physical surface group of the mesh, not empty");
  } else if (const Reader p = e["plane"]; p.present()) {
    region.kind = FixedRegionKind::plane;
    p.object(kFixedPlaneKeys);
    required(p["point"], "a point of the plane [x, y, z] in m");
    required(p["normal"], "the plane's normal [nx, ny, nz]");
    p["point"].get(region.point);
    p["normal"].get(region.normal);
    if (!(region.normal.norm() > 0)) p["normal"].fail("must not be the zero vector");
    region.normal.normalize();
    p["tolerance"].get(region.tolerance, closed(0.0, 1e3));
  } else if (const Reader b = e["box"]; b.present()) {
    region.kind = FixedRegionKind::box;
    read_box_corners(b, region.min, region.max, /*solid=*/false);
  } else {
    region.kind = FixedRegionKind::sphere;
    read_sphere(e["sphere"], region.center, region.radius);
  }
  return region;
}

void read_fixed(const Reader& r, uint32_t& faces, std::vector<FixedRegion>& regions) {
  if (!r.present()) return;  // absent: the default; [] is a free body
  uint32_t out = 0;
  int index = 0;
  for (const Reader& e : r.elements("an array of face names and fixed regions")) {
    if (e.is_object())
      regions.push_back(read_fixed_region(e, "/fixed/" + std::to_string(index)));
    else
      out |= e.pick("face", kFaces)->value;
    ++index;
  }
  faces = out;
}

void read_indenter(const Reader& r, IndenterSpec& ind) {
  r.object(kIndenterKeys);
  r["radius"].get(ind.radius, open_closed(0.0, 1e3));
  r["mass"].get(ind.mass, open_closed(0.0, 1e6));
  r["position"].get(ind.position);
  ind.position_given = ind.position_given || r["position"].present();
  r["force"].get(ind.force, closed(-1e9, 1e9));
  r["workspace_min"].get(ind.workspace_min);
  r["workspace_max"].get(ind.workspace_max);
  constexpr char kAxis[] = "xyz";
  for (int a = 0; a < 3; ++a)  // (both given: the box must not be empty; the build checks a derived corner)
    if (!(ind.workspace_max[a] > ind.workspace_min[a]))
      r["workspace_max"].fail(std::string("must exceed workspace_min in every component (") + kAxis[a] + ": " +
                              fmt(ind.workspace_max[a]) + " <= " + fmt(ind.workspace_min[a]) + ")");
  r["guide"].get(ind.guide, "tool guide", kToolGuides);
}

void read_contact(const Reader& r, ContactSpec& c) {
  r.object(kContactKeys);
  r["tolerance"].get(c.tolerance, closed(0.0, 1.0));
  r["max_iterations"].get(c.max_iterations, 1, 1000000);
}

void read_integrator(const Reader& r, IntegratorSpec& in) {
  r.object(kIntegratorKeys);
  r["type"].get(in.type, "integrator", kIntegrators);
  r["dt"].get(in.dt, open_closed(0.0, 1.0));
  r["damping"].get(in.damping, closed(0.0, 1e6));
  r["cg_tolerance"].get(in.cg_tolerance, open(0.0, 1.0));
  r["cg_max_iterations"].get(in.cg_max_iterations, 1, 1000000);
  r["allow_unstable_dt"].get(in.allow_unstable_dt);
  r["threads"].get(in.threads, 1, kMaxThreads);
}

void read_health(const Reader& r, HealthSpec& h) {
  r.object(kHealthKeys);
  r["enabled"].get(h.enabled);
  r["energy_factor"].get(h.energy_factor, closed_open(1.0, kInf));
  r["max_indenter_speed"].get(h.max_indenter_speed, closed_open(0.0, kInf));
  r["max_penetration"].get(h.max_penetration, closed_open(0.0, kInf));
  r["inversion_sweep_ticks"].get(h.inversion_sweep_ticks, 1, 1000000);
}

void read_gravity(const Reader& r, Vec3& g) {
  r.get(g);
  if (g.norm() > 1e3) r.fail("norm must be at most 1000 m/s^2, got " + fmt(g.norm()));
}

void read_verify(const Reader& r, VerifySpec& v) {
  r.object(kVerifyKeys);
  if (const Reader forces = r["forces"]; forces.present()) {
    v.forces.clear();
    for (const Reader& e : forces.elements("an array of forces in N")) {
      double f = 0.0;
      e.get(f, open_closed(0.0, 1e9));
      v.forces.push_back(f);
    }
  }
  const Reader rest = r["rest"];
  rest.object(kRestKeys);
  rest["velocity_tolerance"].get(v.rest.velocity_tolerance, at_least(0.0));
  rest["force_tolerance"].get(v.rest.force_tolerance, positive());
  rest["window"].get(v.rest.window, positive());
  rest["max_time"].get(v.rest.max_time, open_closed(0.0, 1e6));
}

// The defaults that scale with the scene (a field left out or written as 0 / []): the
// contact tolerance, the rest speed and the verification sweep, from the indenter radius R
// (docs/scene-format.md writes the formulas).
void derive_scale_defaults(Scene& s) {
  const double R = s.indenter.radius;
  if (s.contact.tolerance == 0.0) s.contact.tolerance = kContactToleranceOverRadius * R;
  if (s.verify.rest.velocity_tolerance == 0.0)
    s.verify.rest.velocity_tolerance = kRestTravelOverRadius * R / s.verify.rest.window;
  if (s.verify.forces.empty()) s.verify.forces = default_verify_forces(s.material, R);
}

void read_scene(const Reader& r, const fs::path& base_dir, Scene& s) {
  r.object(kSceneKeys);
  r["name"].get(s.name);
  if (const auto* m = r["model"].pick("model", kModels)) s.model = *m;
  read_body(r["body"], base_dir, s);
  if (s.model == "hex_fem" && s.distribution.type == DistributionType::mesh)
    r["body"]["distribution"]["type"].fail(
        "the hex_fem model meshes a lattice with bricks and cannot use a tetrahedral 'mesh' cloud: use a 'grid' or "
        "'graded_grid' distribution, or the 'mls' model");
  read_mls(r["mls"], s.distribution.type, s.mls);
  read_hex_fem(r["hex_fem"], s.hex_fem);
  if (s.model == "hex_fem" && s.distribution.type != DistributionType::grid &&
      s.distribution.type != DistributionType::graded_grid)
    r["body"]["distribution"]["type"].fail("the hex_fem model meshes a lattice: use a 'grid' or 'graded_grid' distribution");
  read_material(r["material"], s.material);
  if (s.model == "hex_fem")
    for (size_t k = 0; k < s.material.inclusions.size(); ++k)
      if (s.material.inclusions[k].shape == InclusionShape::group)
        r["material"]["inclusions"].elements("an array of inclusions")[k]["group"].fail(
            "a group names a physical volume of a tetrahedral mesh; the hex_fem model meshes a lattice (use a "
            "sphere or a box)");
  if (s.model == "hex_fem" && s.material.law != MaterialLaw::stvk)
    r["material"]["law"].fail("applies to the mls model; the hex_fem model's law is hex_fem.formulation");
  read_fixed(r["fixed"], s.fixed_faces, s.fixed_regions);
  read_indenter(r["indenter"], s.indenter);
  s.contact.tolerance = 0.0;  // left out: derived (derive_scale_defaults)
  read_contact(r["contact"], s.contact);
  read_integrator(r["integrator"], s.integrator);
  read_gravity(r["gravity"], s.gravity);
  s.verify.rest.velocity_tolerance = 0.0;  // left out: derived (derive_scale_defaults)
  read_verify(r["verify"], s.verify);
  read_health(r["health"], s.health);
  derive_scale_defaults(s);
  // A refine object without a size: the spacing the scene asks for (as graded_grid's
  // first_spacing); ignored unless the distribution is a mesh.
  if (s.distribution.refine.size == kDeriveRefineSize)
    s.distribution.refine.size =
        s.distribution.type == DistributionType::mesh ? required_resolution(s).finest_spacing() : 0.0;
  if (s.distribution.type == DistributionType::graded_grid) {
    // Left out (0): the spacing the scene's sweep asks for (core/resolution.h).
    if (s.distribution.first_spacing == 0.0) s.distribution.first_spacing = required_resolution(s).finest_spacing();
    check_graded_grid(r["body"]["distribution"], s);
  }
}

// ---------------------------------------------------------------------------
// JSON text and overrides.

// nlohmann's message without its "[json.exception.x.nnn] " tag and its own position
// ("parse error at line 3, column 0: "), whose column is unreliable.
std::string json_message(const nlohmann::json::exception& e) {
  std::string m = e.what();
  if (const auto tag = m.find("] "); m.rfind("[json.exception.", 0) == 0 && tag != std::string::npos)
    m.erase(0, tag + 2);
  if (m.rfind("parse error", 0) == 0)
    if (const auto colon = m.find(": "); colon != std::string::npos) m.erase(0, colon + 2);
  return m;
}

// Line and column (1-based, columns in bytes) of the 1-based byte position `byte`.
std::string line_column(const std::string& text, std::size_t byte) {
  const std::size_t end = std::min(byte == 0 ? 0 : byte - 1, text.size());  // characters before it
  std::size_t line = 1, line_start = 0;
  for (std::size_t i = 0; i < end; ++i)
    if (text[i] == '\n') ++line, line_start = i + 1;
  return "line " + std::to_string(line) + ", column " + std::to_string(end - line_start + 1);
}

json parse_json(const std::string& text, const std::string& source) {
  try {
    return json::parse(text);
  } catch (const json::parse_error& e) {
    throw SceneError(source, "", "invalid JSON at " + line_column(text, e.byte) + ": " + json_message(e));
  } catch (const json::exception& e) {  // number overflow "... parsing '1e400'": no position given
    const std::string message = json_message(e);
    std::string where;
    if (const auto open = message.find('\''), close = message.rfind('\''); open < close && close != std::string::npos)
      if (const auto at = text.find(message.substr(open + 1, close - open - 1)); at != std::string::npos)
        where = " at " + line_column(text, at + 1);
    throw SceneError(source, "", "invalid JSON" + where + ": " + message);
  }
}

// A JSON literal if the text is one ("12", "[0,0,1]", "\"x\"", "true"), else the bare string.
json override_value(const std::string& text) {
  try {
    json v = json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (!v.is_discarded()) return v;
  } catch (const json::exception&) {
  }
  return text;
}

// The array index a key token names ("2"), or SIZE_MAX.
std::size_t array_index(const std::string& token) {
  std::size_t i = 0;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), i);
  return ec == std::errc() && end == token.data() + token.size() ? i : std::numeric_limits<std::size_t>::max();
}

// Sets root at the dotted `key` (creating missing objects); returns the JSON pointer it set.
std::string apply_override(json& root, const std::string& key, const std::string& value, const std::string& source) {
  const std::string src = Origin::override_source(source, key + "=" + value);
  std::vector<std::string> tokens;
  for (std::size_t start = 0;;) {
    const std::size_t dot = key.find('.', start);
    tokens.push_back(key.substr(start, dot == std::string::npos ? std::string::npos : dot - start));
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  for (const auto& t : tokens)
    if (t.empty()) throw SceneError(src, "", "override key must be a dotted field path such as body.distribution.per_edge");

  json* node = &root;
  std::string path;
  for (const auto& t : tokens) {
    if (node->is_null()) *node = json::object();  // a missing intermediate object
    if (node->is_object()) {
      node = &(*node)[t];
    } else if (const std::size_t i = array_index(t); node->is_array() && i < node->size()) {
      node = &(*node)[i];
    } else {
      throw SceneError(src, path, "cannot set '" + t + "' in " + describe(*node) + " (override " + key + ")");
    }
    path.push_back('/');
    path += pointer_token(t);
  }
  *node = override_value(value);
  return path;
}

}  // namespace

Scene parse_scene(const std::string& json_text, const std::string& source_name, const fs::path& base_dir,
                  const SceneOverrides& overrides, SceneFiles files) {
  json root = parse_json(json_text, source_name);
  if (!root.is_object()) throw SceneError(source_name, "", "the top-level value must be an object, got " + describe(root));

  Origin origin{source_name, {}, files};
  for (const auto& [key, value] : overrides)
    origin.overrides.emplace_back(apply_override(root, key, value, source_name), key + "=" + value);

  Scene scene;
  scene.source = source_name;
  scene.name = fs::path(source_name).stem().string();
  read_scene(Reader(&root, "", origin), base_dir, scene);
  return scene;
}

Scene load_scene(const fs::path& file, const SceneOverrides& overrides, SceneFiles files) {
  const std::string source = file.string();
  const std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(file.c_str(), "rb"), &std::fclose);
  if (!f) throw SceneError(source, "", std::string("cannot read file: ") + std::strerror(errno));
  std::string text;
  char buf[1 << 16];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f.get())) > 0) text.append(buf, n);
  if (std::ferror(f.get())) throw SceneError(source, "", std::string("cannot read file: ") + std::strerror(errno));
  return parse_scene(text, source, file.parent_path(), overrides, files);
}

std::vector<std::string> scene_field_paths() {
  std::vector<std::string> paths;
  add_field_paths(*section_at(""), paths);
  return paths;
}

const char* to_string(IntegratorType t) { return name_for(kIntegrators, t); }
const char* to_string(ToolGuide g) { return name_for(kToolGuides, g); }
const char* to_string(MaterialLaw l) { return name_for(kMaterialLaws, l); }
const char* to_string(HexFormulation f) { return name_for(kHexFormulations, f); }
const char* to_string(DistributionType t) { return name_for(kDistributions, t); }
const char* to_string(HexVolumetricIntegration v) { return name_for(kHexVolumetricIntegrations, v); }
const char* to_string(SupportRule r) { return name_for(kSupportRules, r); }
const char* to_string(IntegrationRule r) { return name_for(kIntegrationRules, r); }
const char* to_string(VolumeRule r) { return name_for(kVolumeRules, r); }

}  // namespace palpate

namespace palpate {

std::vector<double> default_verify_forces(const MaterialSpec& material, double radius) {
  const double E_star = hertz::effective_modulus(material.young_modulus, material.poisson_ratio);
  std::vector<double> forces;
  const double lo = kVerifyDepthsOverRadius[0], hi = kVerifyDepthsOverRadius[1];
  for (int k = 0; k < 10; ++k) forces.push_back(hertz::force((lo + (hi - lo) * k / 9.0) * radius, radius, E_star));
  return forces;
}

}  // namespace palpate
