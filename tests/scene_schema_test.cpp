// The scene schema is written in four places: the structs and their defaults
// (core/scene.h), the reader's keys and ranges (core/scene_schema.h, core/scene_sections.cpp), the wire Scene's
// defaults and range comments (protocol/palpate.capnp) and the field tables of
// docs/scene-format.md. These tests read all four field by field and fail naming
// the field wherever one place disagrees with the others.
#include <capnp/compat/json.h>
#include <capnp/message.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/scene.h"
#include "protocol/scene_wire.h"

#ifndef PALPATE_SOURCE_DIR
#error "PALPATE_SOURCE_DIR must be defined as the repository root path"
#endif

namespace palpate {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const fs::path kSourceDir = PALPATE_SOURCE_DIR;
const std::string kDocs = "docs/scene-format.md";
const std::string kCapnp = "protocol/palpate.capnp";
const std::string kTestSource = "<schema test>";

std::string read_text(const std::string& relative_path) {
  std::ifstream in(kSourceDir / relative_path, std::ios::binary);
  EXPECT_TRUE(in) << "cannot read " << relative_path;
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
  for (std::size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size()))
    s.replace(at, from.size(), to);
  return s;
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// ---------------------------------------------------------------------------
// Every field of Scene, with its JSON pointer.

// A field's value as JSON, for comparisons and messages.
json json_of(const std::string& s) { return s; }
json json_of(const fs::path& p) { return p.string(); }
json json_of(double x) { return x; }
json json_of(int x) { return x; }
json json_of(uint64_t x) { return x; }
json json_of(bool b) { return b; }
json json_of(const Vec3& v) { return json::array({v.x(), v.y(), v.z()}); }
json json_of(const std::vector<double>& v) { return v; }
json json_of(const std::vector<InclusionSpec>& v) {
  json out = json::array();
  for (const InclusionSpec& inc : v) {
    json e = {{"young_modulus", inc.young_modulus}, {"poisson_ratio", inc.poisson_ratio}, {"density", inc.density}};
    if (inc.shape == InclusionShape::sphere)
      e["sphere"] = {{"center", json_of(inc.center)}, {"radius", inc.radius}};
    else
      e["box"] = {{"min", json_of(inc.min)}, {"max", json_of(inc.max)}};
    out.push_back(e);
  }
  return out;
}
template <class Enum>
  requires std::is_enum_v<Enum>
json json_of(Enum e) {
  return to_string(e);
}
// Scene::fixed_faces, the only uint32_t: the face names, as a scene file writes them.
static_assert(std::is_same_v<decltype(Scene::fixed_faces), uint32_t>);
json json_of(uint32_t faces) {
  constexpr std::pair<const char*, uint32_t> kFaceBits[] = {{"bottom", face_bottom}, {"top", face_top},
                                                            {"x_min", face_x_min},   {"x_max", face_x_max},
                                                            {"y_min", face_y_min},   {"y_max", face_y_max}};
  json names = json::array();
  for (const auto& [name, bit] : kFaceBits)
    if (faces & bit) names.push_back(name);
  return names;
}

struct Field {
  std::string_view pointer;  // in a scene file; empty for the fields the reader derives
  std::string_view member;   // of Scene
  std::string_view sample;   // JSON: a value other than the default that is valid on its own
  json (*value)(const Scene&);

  std::string name() const { return pointer.empty() ? "Scene::" + std::string(member) : std::string(pointer); }
};

#define SCENE_FIELD(pointer, member, sample) \
  Field { pointer, #member, sample, [](const Scene& s) { return json_of(s.member); } }

// In the order of docs/scene-format.md (and of scene_field_paths()).
const Field kFields[] = {
    SCENE_FIELD("/name", name, R"("sample")"),
    SCENE_FIELD("", source, ""),
    SCENE_FIELD("/model", model, R"("hex_fem")"),
    SCENE_FIELD("/body/box/min", box.min, "[-1, -1, -3]"),
    SCENE_FIELD("/body/box/max", box.max, "[1, 2, 0]"),
    SCENE_FIELD("", box_given, ""),
    SCENE_FIELD("/body/distribution/type", distribution.type, R"("jittered_grid")"),
    SCENE_FIELD("/body/distribution/per_edge", distribution.per_edge, "12"),
    SCENE_FIELD("/body/distribution/spacing", distribution.spacing, "0.25"),
    SCENE_FIELD("/body/distribution/jitter", distribution.jitter, "0.2"),
    SCENE_FIELD("/body/distribution/seed", distribution.seed, "7"),
    SCENE_FIELD("/body/distribution/first_spacing", distribution.first_spacing, "0.05"),
    SCENE_FIELD("", distribution.focus_given, ""),
    SCENE_FIELD("/body/distribution/focus", distribution.focus, "[0.5, 0, 0]"),
    SCENE_FIELD("/body/distribution/node_file", distribution.node_file, R"("nodes.txt")"),
    SCENE_FIELD("/body/distribution/file", distribution.mesh_file, R"("cube.msh")"),
    SCENE_FIELD("/body/distribution/refine/size", distribution.refine.size, "0.002"),
    SCENE_FIELD("/body/distribution/refine/growth", distribution.refine.growth, "1.5"),
    SCENE_FIELD("/body/distribution/refine/max_size", distribution.refine.max_size, "0.01"),
    SCENE_FIELD("/mls/neighbors", mls.neighbors, "26"),
    SCENE_FIELD("/mls/max_neighbors", mls.max_neighbors, "64"),
    SCENE_FIELD("/mls/support_factor", mls.support_factor, "1.5"),
    SCENE_FIELD("/mls/support_rule", mls.support_rule, R"("kth_distance")"),
    SCENE_FIELD("/mls/integration", mls.integration, R"("consistent")"),
    SCENE_FIELD("/mls/volumes", mls.volumes, R"("lattice")"),
    SCENE_FIELD("/mls/hourglass", mls.hourglass, "0.5"),
    SCENE_FIELD("/mls/regularization", mls.regularization, "1e-4"),
    SCENE_FIELD("/mls/mass_floor", mls.mass_floor, "0.5"),
    SCENE_FIELD("/hex_fem/formulation", hex_fem.formulation, R"("corotational")"),
    SCENE_FIELD("/hex_fem/volumetric_integration", hex_fem.volumetric_integration, R"("reduced")"),
    SCENE_FIELD("/material/young_modulus", material.young_modulus, "2e4"),
    SCENE_FIELD("/material/poisson_ratio", material.poisson_ratio, "0.45"),
    SCENE_FIELD("/material/density", material.density, "1100"),
    SCENE_FIELD("/material/volume_stiffness", material.volume_stiffness, "100"),
    SCENE_FIELD("/material/law", material.law, R"("corotational")"),
    SCENE_FIELD("/material/inclusions", material.inclusions,
                R"([{"sphere": {"center": [0, 0, -0.5], "radius": 0.25}, "young_modulus": 3e4, "poisson_ratio": 0.3}])"),
    SCENE_FIELD("/fixed", fixed_faces, R"(["bottom"])"),
    SCENE_FIELD("/indenter/radius", indenter.radius, "0.25"),
    SCENE_FIELD("/indenter/mass", indenter.mass, "2"),
    SCENE_FIELD("", indenter.position_given, ""),
    SCENE_FIELD("/indenter/position", indenter.position, "[0.1, 0.2, 0.5]"),
    SCENE_FIELD("/indenter/force", indenter.force, "30"),
    SCENE_FIELD("/indenter/workspace_min", indenter.workspace_min, "[-2, -2, -3]"),
    SCENE_FIELD("/indenter/workspace_max", indenter.workspace_max, "[2, 2, 1]"),
    SCENE_FIELD("/indenter/guide", indenter.guide, R"("free")"),
    SCENE_FIELD("/contact/tolerance", contact.tolerance, "1e-5"),
    SCENE_FIELD("/contact/max_iterations", contact.max_iterations, "50"),
    SCENE_FIELD("/integrator/type", integrator.type, R"("implicit_euler")"),
    SCENE_FIELD("/integrator/dt", integrator.dt, "0.01"),
    SCENE_FIELD("/integrator/damping", integrator.damping, "2.5"),
    SCENE_FIELD("/integrator/cg_tolerance", integrator.cg_tolerance, "1e-6"),
    SCENE_FIELD("/integrator/cg_max_iterations", integrator.cg_max_iterations, "500"),
    SCENE_FIELD("/integrator/allow_unstable_dt", integrator.allow_unstable_dt, "true"),
    SCENE_FIELD("/integrator/threads", integrator.threads, "2"),
    SCENE_FIELD("/integrator/max_interval", integrator.max_interval, "4"),
    SCENE_FIELD("/gravity", gravity, "[0, 0, -9.81]"),
    SCENE_FIELD("/verify/forces", verify.forces, "[10, 50]"),
    SCENE_FIELD("/verify/rest/velocity_tolerance", verify.rest.velocity_tolerance, "1e-3"),
    SCENE_FIELD("/verify/rest/force_tolerance", verify.rest.force_tolerance, "1e-2"),
    SCENE_FIELD("/verify/rest/window", verify.rest.window, "0.1"),
    SCENE_FIELD("/verify/rest/max_time", verify.rest.max_time, "30"),
    SCENE_FIELD("/health/enabled", health.enabled, "false"),
    SCENE_FIELD("/health/energy_factor", health.energy_factor, "4"),
    SCENE_FIELD("/health/max_indenter_speed", health.max_indenter_speed, "2"),
    SCENE_FIELD("/health/max_penetration", health.max_penetration, "0.01"),
    SCENE_FIELD("/health/inversion_sweep_ticks", health.inversion_sweep_ticks, "8"),
};

#undef SCENE_FIELD

// A member added to (or removed from) a scene struct stops these bindings compiling.
// Add it to kFields above, read it in core/scene_sections.cpp (its key in core/scene_schema.h), carry it in protocol/palpate.capnp
// and document it in docs/scene-format.md; the tests below check that all four agree.
[[maybe_unused]] void every_member_is_in_kFields(const Scene& s) {
  [[maybe_unused]] const auto& [name, source, model, box, box_given, distribution, mls, hex_fem, material, fixed_faces,
                                fixed_regions /* /fixed objects: file scenes only */, indenter,
                                contact, integrator, gravity, verify, health] = s;
  [[maybe_unused]] const auto& [min, max] = s.box;
  [[maybe_unused]] const auto& [type, per_edge, spacing, jitter, first_spacing, focus_given, focus, seed, node_file,
                                mesh_file, refine] = s.distribution;
  [[maybe_unused]] const auto& [refine_size, refine_growth, refine_max_size] = s.distribution.refine;
  [[maybe_unused]] const auto& [neighbors, max_neighbors, support_factor, support_rule, integration, volumes, hourglass,
                                regularization, mass_floor] = s.mls;
  [[maybe_unused]] const auto& [formulation, volumetric_integration] = s.hex_fem;
  [[maybe_unused]] const auto& [young_modulus, poisson_ratio, density, volume_stiffness, law, inclusions] = s.material;
  [[maybe_unused]] const auto& [radius, mass, position_given, position, force, workspace_min, workspace_max, guide] =
      s.indenter;
  [[maybe_unused]] const auto& [tolerance, max_iterations] = s.contact;
  [[maybe_unused]] const auto& [integrator_type, dt, damping, cg_tolerance, cg_max_iterations, allow_unstable_dt,
                                threads, max_interval] =
      s.integrator;
  [[maybe_unused]] const auto& [forces, rest] = s.verify;
  [[maybe_unused]] const auto& [velocity_tolerance, force_tolerance, window, max_time] = s.verify.rest;
  [[maybe_unused]] const auto& [enabled, energy_factor, max_indenter_speed, max_penetration, inversion_sweep_ticks] =
      s.health;
}

// Fields whose default is not a value a scene file could write: the source's stem,
// "no file", the top face under the indenter, the indenter just touching the body.
// Scene-file fields not (yet) on the wire: a wire scene leaves them at their defaults.
// The refinement that follows the tool refines a mesh file (wire scenes name no mesh file).
const std::set<std::string> kFileOnlyFields = {"/body/distribution/refine/size", "/body/distribution/refine/growth",
                                               "/body/distribution/refine/max_size"};
// Wire fields that are parts of a file field: Scene.fixedRegions are the object elements
// of the file's `fixed` (protocol/scene_wire.cpp merges them; FixedRegionsCrossTheWire).
const std::map<std::string, std::string> kWirePartsOfFileFields = {{"/fixed_regions", "/fixed"}};

const std::set<std::string> kDerivedDefaults = {"/name", "/body/distribution/focus", "/body/distribution/node_file",
                                                "/body/distribution/file", "/indenter/position",
                                                "/indenter/workspace_min", "/indenter/workspace_max",
                                                // scale with the indenter radius (core/scene.h)
                                                "/contact/tolerance", "/verify/forces",
                                                "/verify/rest/velocity_tolerance",
                                                // from the sweep and the inclusions (core/resolution.h)
                                                "/body/distribution/first_spacing",
                                                "/body/distribution/refine/size"};

// "pointer: expected vs actual" for every field where the scenes differ; empty when equal.
std::string differences(const Scene& expected, const Scene& actual) {
  std::string out;
  for (const Field& f : kFields)
    if (const json e = f.value(expected), a = f.value(actual); e != a)
      out += "\n  " + f.name() + ": expected " + e.dump() + ", got " + a.dump();
  return out;
}

// How two lists of field pointers differ: the entries only one has, else the first
// place where their order differs; empty when equal.
std::string list_differences(const std::vector<std::string>& a, const std::string& a_name,
                             const std::vector<std::string>& b, const std::string& b_name) {
  std::string out;
  const auto only_in = [&out](const std::vector<std::string>& x, const std::string& x_name,
                              const std::vector<std::string>& y) {
    for (const std::string& p : x)
      if (std::find(y.begin(), y.end(), p) == y.end()) out += "\n  " + p + " only in " + x_name;
  };
  only_in(a, a_name, b);
  only_in(b, b_name, a);
  if (out.empty())
    for (std::size_t i = 0; i < a.size(); ++i)
      if (a[i] != b[i]) {
        out = "\n  the order differs at " + a[i] + " (" + a_name + ") / " + b[i] + " (" + b_name + ")";
        break;
      }
  return out;
}

void expect_same(const Scene& expected, const Scene& actual, const std::string& what) {
  const std::string d = differences(expected, actual);
  EXPECT_TRUE(d.empty()) << what << d;
}

Scene parse(const std::string& text) { return parse_scene(text, kTestSource, "."); }

// The JSON text of a scene that sets only `pointer` to the JSON `value`.
std::string scene_setting(std::string_view pointer, const std::string& value) {
  std::string open, close;
  for (std::size_t at = 1; at <= pointer.size();) {
    const std::size_t end = std::min(pointer.find('/', at), pointer.size());
    open += "{\"" + std::string(pointer.substr(at, end - at)) + "\": ";
    close += "}";
    at = end + 1;
  }
  return open + value + close;
}

// The SceneError that parsing `text` throws, if any.
std::optional<SceneError> error_of(const std::string& text) {
  try {
    parse(text);
  } catch (const SceneError& e) {
    return e;
  }
  return std::nullopt;
}

// Shortest text that reads back as x.
std::string number_text(double x) {
  char buf[64];
  const auto end = std::to_chars(buf, buf + sizeof buf, x).ptr;
  return std::string(buf, end);
}

std::string integer_text(long double x) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.0Lf", x);
  return buf;
}

// ---------------------------------------------------------------------------
// The wire.

// The JSON of a wire scene like protocol/scene_wire.cpp's, but with default-valued fields too.
json json_with_defaults(wire::Scene::Reader scene) {
  capnp::JsonCodec codec;
  codec.handleByAnnotation<wire::Scene>();
  codec.setHasMode(capnp::HasMode::NON_NULL);
  return json::parse(codec.encode(scene).cStr());
}

// The wire scene a client builds to send `scene_json` (the wire's own JSON decoder).
Scene through_the_wire(const std::string& scene_json) {
  capnp::MallocMessageBuilder message;
  auto scene = message.initRoot<wire::Scene>();
  scene_json_to_wire(scene_json, kTestSource, scene);
  return scene_from_wire(scene, kTestSource, ".");
}

// Each leaf of `value` by JSON pointer (arrays are leaves).
void flatten(const json& value, const std::string& pointer, std::map<std::string, json>& out) {
  if (!value.is_object()) {
    out[pointer] = value;
    return;
  }
  for (const auto& [key, child] : value.items()) flatten(child, pointer + "/" + key, out);
}

// Every wire field that has a capnp default (the primitives), by the JSON pointer of its
// file field: a wire scene with every struct set and nothing else, encoded in full.
std::map<std::string, json> wire_defaults() {
  json skeleton = json::object();
  for (const std::string& path : scene_field_paths()) {
    if (kFileOnlyFields.count(path)) continue;  // their objects are not on the wire either
    for (std::size_t slash = path.find('/', 1); slash != std::string::npos; slash = path.find('/', slash + 1))
      skeleton[json::json_pointer(path.substr(0, slash))] = json::object();
  }
  capnp::MallocMessageBuilder message;
  auto scene = message.initRoot<wire::Scene>();
  scene_json_to_wire(skeleton.dump(), kTestSource, scene);
  std::map<std::string, json> out;
  flatten(json_with_defaults(scene), "", out);
  return out;
}

// One field of a wire struct reachable from Scene, as palpate.capnp writes it.
struct WireField {
  std::string pointer;  // of the scene-file field it carries
  std::string type;     // "Float64", "List(Float64)", ...
  std::string comment;  // the text after '#' on its line
  int line;
};

// The wire fields reachable from struct Scene, read from the schema's text.
std::vector<WireField> wire_fields() {
  struct Raw {
    std::string name, type, comment;
    int line;
  };
  std::map<std::string, std::vector<Raw>> structs;
  const std::regex struct_begin(R"(^struct (\w+) \{)");
  const std::regex field(R"(^\s*(\w+)\s+@\d+\s*:\s*([\w()]+)([^;]*);\s*(?:#\s*(.*))?$)");
  const std::regex json_name(R"re(\$Json\.name\("(\w+)"\))re");
  const std::vector<std::string> lines = lines_of(read_text(kCapnp));
  std::string current;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    std::smatch m;
    if (std::regex_search(lines[i], m, struct_begin)) {
      current = m[1];
    } else if (!lines[i].empty() && lines[i][0] == '}') {
      current.clear();
    } else if (!current.empty() && std::regex_match(lines[i], m, field)) {
      std::string name = m[1];
      const std::string rest = m[3];
      if (std::smatch n; std::regex_search(rest, n, json_name)) name = n[1];
      structs[current].push_back({name, m[2], m[4], static_cast<int>(i + 1)});
    }
  }
  std::vector<WireField> out;
  const auto walk = [&](const auto& self, const std::string& struct_name, const std::string& pointer) -> void {
    for (const Raw& f : structs[struct_name]) {
      if (structs.count(f.type)) self(self, f.type, pointer + "/" + f.name);
      else out.push_back({pointer + "/" + f.name, f.type, f.comment, f.line});
    }
  };
  walk(walk, "Scene", "");
  return out;
}

// ---------------------------------------------------------------------------
// docs/scene-format.md: the field tables and the ranges they write.

struct DocField {
  std::string pointer, type, default_cell, allowed;
  int line;
};

struct DocTable {
  std::string pointer;  // of the object whose keys the table lists
  std::vector<DocField> rows;
};

// The cells of a Markdown table row ("\|" is a '|' inside a cell), trimmed.
std::vector<std::string> cells_of(const std::string& row) {
  std::vector<std::string> cells;
  std::string cell;
  for (std::size_t i = 1; i < row.size(); ++i) {
    if (row[i] == '\\' && i + 1 < row.size() && row[i + 1] == '|') {
      cell += '|';
      ++i;
    } else if (row[i] == '|') {
      const auto first = cell.find_first_not_of(' '), last = cell.find_last_not_of(' ');
      cells.push_back(first == std::string::npos ? "" : cell.substr(first, last - first + 1));
      cell.clear();
    } else {
      cell += row[i];
    }
  }
  return cells;
}

// The text of a cell that is exactly one code span (`18`), else nullopt.
std::optional<std::string> code_span(const std::string& cell) {
  if (cell.size() < 2 || cell.front() != '`' || cell.back() != '`') return std::nullopt;
  const std::string inner = cell.substr(1, cell.size() - 2);
  if (inner.find('`') != std::string::npos) return std::nullopt;
  return inner;
}

// Every code span of a text, in order.
std::vector<std::string> code_spans(const std::string& text) {
  std::vector<std::string> out;
  for (std::size_t open = text.find('`'); open != std::string::npos;) {
    const std::size_t close = text.find('`', open + 1);
    if (close == std::string::npos) break;
    out.push_back(text.substr(open + 1, close - open - 1));
    open = text.find('`', close + 1);
  }
  return out;
}

// The field tables ("| key | type | default | ..."), each under the heading that names
// its object: "## Top level", "### `body.box`".
std::vector<DocTable> doc_tables() {
  const std::vector<std::string> lines = lines_of(read_text(kDocs));
  std::vector<DocTable> tables;
  std::string section;         // the JSON pointer the last heading names
  bool section_named = false;  // false: the last heading names no object
  bool in_code = false;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string& line = lines[i];
    if (line.rfind("```", 0) == 0) in_code = !in_code;
    if (in_code) continue;
    if (line.rfind("#", 0) == 0) {
      section.clear();
      section_named = line.find("Top level") != std::string::npos;
      const std::vector<std::string> spans = code_spans(line);
      if (spans.size() == 1 && std::regex_match(spans[0], std::regex(R"([a-z_]+(\.[a-z_]+)*)"))) {
        section = "/" + replace_all(spans[0], ".", "/");
        section_named = true;
      }
      continue;
    }
    if (line.rfind("| key | type | default |", 0) != 0) continue;
    EXPECT_TRUE(section_named) << kDocs << ":" << i + 1 << ": a field table under a heading that names no object";
    const std::vector<std::string> header = cells_of(line);
    const auto column = [&](const std::string& name) {
      return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
    };
    DocTable table{section, {}};
    for (; i + 1 < lines.size() && lines[i + 1].rfind("|", 0) == 0; ++i) {
      if (lines[i + 1].rfind("|---", 0) == 0) continue;
      std::vector<std::string> row = cells_of(lines[i + 1]);
      row.resize(header.size());
      const std::optional<std::string> key = code_span(row[column("key")]);
      EXPECT_TRUE(key.has_value()) << kDocs << ":" << i + 2 << ": the key is not one code span";
      table.rows.push_back({table.pointer + "/" + key.value_or("?"), row[column("type")], row[column("default")],
                            row[column("allowed")], static_cast<int>(i + 2)});
    }
    tables.push_back(std::move(table));
  }
  return tables;
}

// The documented fields in document order: an object row stands for the table of
// that object or, when it has none (body), for the tables of its members.
std::vector<DocField> doc_fields() {
  const std::vector<DocTable> tables = doc_tables();
  std::vector<DocField> out;
  std::set<std::string> reached;
  const auto parent_of = [](const std::string& pointer) { return pointer.substr(0, pointer.rfind('/')); };
  const auto expand = [&](const auto& self, const std::string& pointer) -> void {
    const auto own = std::find_if(tables.begin(), tables.end(), [&](const DocTable& t) { return t.pointer == pointer; });
    if (own != tables.end()) {
      reached.insert(pointer);
      for (const DocField& f : own->rows) {
        if (f.type == "object") self(self, f.pointer);
        else out.push_back(f);
      }
      return;
    }
    bool found = false;
    for (const DocTable& t : tables)
      if (!t.pointer.empty() && parent_of(t.pointer) == pointer) {
        found = true;
        self(self, t.pointer);
      }
    EXPECT_TRUE(found) << kDocs << ": no table for the object " << pointer;
  };
  expand(expand, "");
  for (const DocTable& t : tables)
    EXPECT_TRUE(reached.count(t.pointer)) << kDocs << ": the table of " << t.pointer << " is not reached from the top level";
  return out;
}

// A range as written in the docs ("(0, 10]", "≥ 0, < 2^64", "0 or [neighbors, 128]")
// or in a palpate.capnp comment (ASCII: ">= 0", "[1, inf)").
struct Bound {
  double value;
  bool open;
};
struct DocRange {
  std::optional<Bound> lo, hi;
  bool zero_too = false;  // "0 or [...]"

  bool operator==(const DocRange& o) const {
    const auto same = [](const std::optional<Bound>& a, const std::optional<Bound>& b) {
      return a.has_value() == b.has_value() && (!a || (a->value == b->value && a->open == b->open));
    };
    return same(lo, o.lo) && same(hi, o.hi) && zero_too == o.zero_too;
  }
  std::string text() const {
    std::string s = zero_too ? "0 or " : "";
    s += lo ? (lo->open ? "(" : "[") + number_text(lo->value) : "(-inf";
    s += ", ";
    s += hi ? number_text(hi->value) + (hi->open ? ")" : "]") : "inf)";
    return s;
  }
};

// A bound's text: a number, 2^64, inf, or a field of the same object (its default).
std::optional<double> bound_value(const std::string& token) {
  if (token == "inf") return INFINITY;
  if (token == "2^64") return 18446744073709551616.0;
  if (token == "neighbors") return Scene{}.mls.neighbors;
  char* end = nullptr;
  const double x = std::strtod(token.c_str(), &end);
  if (token.empty() || *end != '\0') return std::nullopt;
  return x;
}

// The range in `text`, or nullopt when it writes none (or one this cannot read).
std::optional<DocRange> range_in(std::string text) {
  text = replace_all(replace_all(replace_all(text, "−", "-"), "≥", ">="), "≤", "<=");
  DocRange r;
  r.zero_too = text.rfind("0 or ", 0) == 0;
  static const std::regex interval(R"(([\[(])\s*([-+\w.^]+)\s*,\s*([-+\w.^]+)\s*([\])]))");
  static const std::regex comparison(R"((>=|<=|>|<)\s*([-+\w.^]+))");
  std::smatch m;
  if (std::regex_search(text, m, interval)) {
    const auto lo = bound_value(m[2]), hi = bound_value(m[3]);
    if (!lo || !hi) return std::nullopt;
    r.lo = Bound{*lo, m[1] == "("};
    if (*hi != INFINITY) r.hi = Bound{*hi, m[4] == ")"};
    return r;
  }
  for (auto it = std::sregex_iterator(text.begin(), text.end(), comparison); it != std::sregex_iterator(); ++it) {
    const std::string op = (*it)[1];
    const auto value = bound_value((*it)[2]);
    if (!value) return std::nullopt;
    (op[0] == '>' ? r.lo : r.hi) = Bound{*value, op.size() == 1};
  }
  if (!r.lo && !r.hi) return std::nullopt;
  return r;
}

bool is_numeric(const DocField& f) {
  return f.type == "number" || f.type == "integer" || f.type == "array of numbers";
}

// ---------------------------------------------------------------------------
// (a) The Scene's fields, the reader's and the empty wire scene.

TEST(SceneSchema, TheFieldListIsTheReaders) {
  std::vector<std::string> listed;
  for (const Field& f : kFields)
    if (!f.pointer.empty()) listed.emplace_back(f.pointer);
  const std::string d = list_differences(listed, "kFields (this test)", scene_field_paths(), "core/scene_schema.h");
  EXPECT_TRUE(d.empty()) << "kFields and the keys core/scene_schema.h lists differ:" << d;
}

TEST(SceneSchema, EmptyFileLeavesEveryStructDefault) {
  Scene defaults;
  defaults.name = "my_scene";  // the source's stem
  defaults.source = "some/dir/my_scene.json";
  defaults.verify.forces = default_verify_forces(defaults.material, defaults.indenter.radius);  // derived from R
  expect_same(defaults, parse_scene("{}", "some/dir/my_scene.json", "some/dir"),
              "parse_scene(\"{}\") against core/scene.h's defaults:");
}

TEST(SceneSchema, EmptyWireSceneIsTheEmptyFile) {
  capnp::MallocMessageBuilder message;
  const auto scene = message.initRoot<wire::Scene>();
  expect_same(parse("{}"), scene_from_wire(scene, kTestSource, "."),
              "a default-initialised wire::Scene against parse_scene(\"{}\"):");
}

// Each sample really is another value of its own field, so the round trips below test something.
TEST(SceneSchema, SamplesChangeTheirField) {
  const Scene defaults = parse("{}");
  for (const Field& f : kFields) {
    if (f.pointer.empty()) continue;
    const std::string text = scene_setting(f.pointer, std::string(f.sample));
    try {
      const Scene s = parse(text);
      EXPECT_NE(f.value(s), f.value(defaults)) << f.pointer << ": the sample " << f.sample << " is the default";
    } catch (const SceneError& e) {
      ADD_FAILURE() << f.pointer << ": the sample " << text << " is refused: " << e.what();
    }
  }
}

// ---------------------------------------------------------------------------
// (b) The wire: every capnp default is the file default, every value crosses it.

TEST(SceneSchema, WireDefaultsAreTheFileDefaults) {
  const Scene defaults = parse("{}");
  const std::vector<std::string> paths = scene_field_paths();
  for (const auto& [pointer, value] : wire_defaults()) {
    if (std::find(paths.begin(), paths.end(), pointer) == paths.end()) {
      ADD_FAILURE() << kCapnp << ": the wire field at " << pointer << " is no scene-file field";
      continue;
    }
    const std::string text = scene_setting(pointer, value.dump());
    try {
      expect_same(defaults, parse(text),
                  kCapnp + ": the capnp default of " + pointer + " (" + value.dump() +
                      ") is not the file's default; a client that sets it explicitly gets the file default "
                      "instead. Scene from " + text + " against parse_scene(\"{}\"):");
    } catch (const SceneError& e) {
      ADD_FAILURE() << kCapnp << ": the capnp default of " << pointer << " is refused by the reader: " << e.what();
    }
  }
}

// Each field set explicitly on the wire to its default, to the capnp default and to another
// value decodes to exactly what the same scene file gives.
TEST(SceneSchema, EveryFieldCrossesTheWire) {
  const Scene struct_defaults;
  const std::map<std::string, json> capnp_defaults = wire_defaults();
  for (const Field& f : kFields) {
    if (f.pointer.empty() || kFileOnlyFields.count(std::string(f.pointer))) continue;
    const std::string pointer(f.pointer);
    std::vector<std::string> values = {std::string(f.sample)};
    if (!kDerivedDefaults.count(pointer)) values.push_back(f.value(struct_defaults).dump());
    if (const auto it = capnp_defaults.find(pointer); it != capnp_defaults.end()) values.push_back(it->second.dump());
    for (const std::string& value : values) {
      const std::string text = scene_setting(pointer, value);
      try {
        expect_same(parse(text), through_the_wire(text),
                    pointer + " = " + value + " sent on the wire against the scene file " + text + ":");
      } catch (const SceneError& e) {
        ADD_FAILURE() << pointer << " = " << value << ": " << e.what();
      }
    }
  }
}

// Every file field has its wire field and the other way round (the wire's order is its ordinals').
TEST(SceneSchema, WireFieldsAreTheReadersFields) {
  std::set<std::string> wire_paths, file_paths;
  for (const WireField& f : wire_fields()) wire_paths.insert(f.pointer);
  for (const std::string& p : scene_field_paths()) file_paths.insert(p);
  for (const std::string& p : file_paths)
    if (!kFileOnlyFields.count(p)) {
      EXPECT_TRUE(wire_paths.count(p)) << kCapnp << ": the scene-file field " << p << " has no wire field";
    }
  for (const std::string& p : wire_paths) {
    const auto part = kWirePartsOfFileFields.find(p);
    EXPECT_TRUE(file_paths.count(part == kWirePartsOfFileFields.end() ? p : part->second))
        << kCapnp << ": the wire field at " << p << " is no scene-file field";
  }
}

// The region objects of `fixed` (a group, a plane, a box, a sphere) cross the wire in
// Scene.fixedRegions and come back as the same regions, after the faces, with the same
// pointers in messages.
TEST(SceneSchema, FixedRegionsCrossTheWire) {
  const std::string text = R"({"fixed": ["bottom", {"group": "base"},
      {"plane": {"point": [0, 0, -1.5], "normal": [0, 0, 2], "tolerance": 0.01}},
      {"box": {"min": [-1, -1, -2], "max": [1, 1, -1.9]}},
      {"sphere": {"center": [0, 0, -2], "radius": 0.3}}]})";
  const Scene file = parse(text), wire = through_the_wire(text);
  EXPECT_EQ(file.fixed_faces, wire.fixed_faces);
  ASSERT_EQ(file.fixed_regions.size(), 4u);
  ASSERT_EQ(wire.fixed_regions.size(), file.fixed_regions.size());
  for (std::size_t k = 0; k < file.fixed_regions.size(); ++k) {
    const FixedRegion &a = file.fixed_regions[k], &b = wire.fixed_regions[k];
    EXPECT_EQ(a.kind, b.kind) << k;
    EXPECT_EQ(a.group, b.group) << k;
    EXPECT_EQ(a.point, b.point) << k;
    EXPECT_EQ(a.normal, b.normal) << k;
    EXPECT_EQ(a.tolerance, b.tolerance) << k;
    EXPECT_EQ(a.min, b.min) << k;
    EXPECT_EQ(a.max, b.max) << k;
    EXPECT_EQ(a.center, b.center) << k;
    EXPECT_EQ(a.radius, b.radius) << k;
    EXPECT_EQ(a.field, b.field) << k;
  }
  // Regions alone: the faces are an empty list, not null.
  const Scene regions_only = through_the_wire(R"({"fixed": [{"group": "base"}]})");
  EXPECT_EQ(regions_only.fixed_faces, 0u);
  EXPECT_EQ(regions_only.fixed_regions.size(), 1u);
  // Regions with null faces are ambiguous (the default faces, or none?) and refused.
  capnp::MallocMessageBuilder message;
  auto scene = message.initRoot<wire::Scene>();
  scene.initFixedRegions(1)[0].setGroup("base");
  try {
    scene_from_wire(scene, kTestSource, ".");
    ADD_FAILURE() << "fixedRegions with a null fixed list were accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/fixed") << e.what();
    EXPECT_EQ(e.source(), kTestSource) << e.what();
  }
}

// An inclusion's Poisson ratio of 0 is a value, not "absent" (the codec's defaults-omitted
// encoding would drop it and the reader would call it missing); a density of 0 is the
// matrix's.
TEST(SceneSchema, InclusionMaterialCrossesTheWire) {
  const std::string text = R"({"material": {"density": 1200, "inclusions": [
      {"box": {"min": [-0.1, -0.1, -0.6], "max": [0.1, 0.1, -0.4]}, "young_modulus": 5e4, "poisson_ratio": 0},
      {"sphere": {"center": [0, 0, -0.5], "radius": 0.25}, "young_modulus": 3e4, "poisson_ratio": 0.3,
       "density": 2000}]}})";
  const Scene file = parse(text), wire = through_the_wire(text);
  ASSERT_EQ(wire.material.inclusions.size(), 2u);
  EXPECT_EQ(file.material.inclusions, wire.material.inclusions);
  EXPECT_EQ(wire.material.inclusions[0].poisson_ratio, 0.0);
  EXPECT_EQ(wire.material.inclusions[0].density, 1200.0);
  EXPECT_EQ(wire.material.inclusions[1].density, 2000.0);
}

// ---------------------------------------------------------------------------
// (c) docs/scene-format.md: its fields are the reader's, its defaults the structs'.

TEST(SceneSchema, DocumentedFieldsAreTheReadersFields) {
  std::vector<std::string> documented;
  for (const DocField& f : doc_fields()) documented.push_back(f.pointer);
  const std::string d = list_differences(documented, kDocs, scene_field_paths(), "core/scene_schema.h");
  EXPECT_TRUE(d.empty()) << kDocs << "'s field tables (in document order) and core/scene_schema.h's keys (in reading order) differ:"
                         << d;
}

TEST(SceneSchema, DocumentedDefaultsAreTheStructDefaults) {
  const Scene defaults = parse("{}");
  for (const DocField& f : doc_fields()) {
    const std::string where = kDocs + ":" + std::to_string(f.line) + ": " + f.pointer;
    const std::optional<std::string> value = code_span(f.default_cell);
    if (kDerivedDefaults.count(f.pointer)) {
      EXPECT_FALSE(value.has_value()) << where << ": a derived default documented as the value " << *value;
      continue;
    }
    if (!value) {
      ADD_FAILURE() << where << ": the default \"" << f.default_cell << "\" is not one JSON value in a code span";
      continue;
    }
    const std::string text = scene_setting(f.pointer, *value);
    try {
      expect_same(defaults, parse(text), where + ": the documented default " + *value +
                                             " is not core/scene.h's. Scene from " + text + " against parse_scene(\"{}\"):");
    } catch (const SceneError& e) {
      ADD_FAILURE() << where << ": the documented default " << *value << " is refused: " << e.what();
    }
  }
}

// Fields are checked in the order of the document: with every field wrong, the reader
// reports them one at a time in that order.
TEST(SceneSchema, FieldsAreCheckedInDocumentOrder) {
  const std::vector<DocField> documented = doc_fields();
  json scene = json::object();
  for (const DocField& f : documented) scene[json::json_pointer(f.pointer)] = json::object();  // wrong for every type
  for (const DocField& f : documented) {
    const std::optional<SceneError> e = error_of(scene.dump());
    ASSERT_TRUE(e.has_value()) << f.pointer << " = {} is accepted";
    ASSERT_EQ(e->field(), f.pointer) << kDocs << ":" << f.line << ": " << f.pointer
                                     << " is documented next, but the reader checks another field first: " << e->what();
    const json::json_pointer at(f.pointer);
    scene[at.parent_pointer()].erase(at.back());
  }
  EXPECT_FALSE(error_of(scene.dump()).has_value());
}

// Every JSON example of a shipped scene is that file, character for character.
TEST(SceneSchema, DocumentedExamplesAreTheShippedScenes) {
  const std::vector<std::string> lines = lines_of(read_text(kDocs));
  const std::regex example_heading(R"(^#+ Example: `(scenes/[\w.]+\.json)`)");
  int examples = 0;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    std::smatch m;
    if (!std::regex_search(lines[i], m, example_heading)) continue;
    const std::string file = m[1];
    std::size_t open = i + 1;
    while (open < lines.size() && lines[open].rfind("```json", 0) != 0) ++open;
    ASSERT_LT(open, lines.size()) << kDocs << ":" << i + 1 << ": no ```json block after the heading";
    std::string block;
    std::size_t close = open + 1;
    for (; close < lines.size() && lines[close].rfind("```", 0) != 0; ++close) block += lines[close] + "\n";
    EXPECT_EQ(block, read_text(file)) << kDocs << ":" << open + 2 << ": the example of " << file << " is not the file";
    ++examples;
  }
  EXPECT_GT(examples, 0);
}

// ---------------------------------------------------------------------------
// (d) Ranges: the documented bounds are the reader's, and palpate.capnp writes the same.

TEST(SceneSchema, DocumentedRangesAreTheReadersRanges) {
  for (const DocField& f : doc_fields()) {
    if (!is_numeric(f)) continue;
    const std::string where = kDocs + ":" + std::to_string(f.line) + ": " + f.pointer;
    const std::optional<DocRange> range = range_in(f.allowed);
    if (!range) {
      ADD_FAILURE() << where << ": no range in \"" << f.allowed << "\"";
      continue;
    }
    const bool integer = f.type == "integer";
    const bool element = f.type == "array of numbers";  // each element in the range
    const std::string field = element ? f.pointer + "/0" : f.pointer;
    const auto text_of = [&](long double x) {
      const std::string number = integer ? integer_text(x) : number_text(static_cast<double>(x));
      return scene_setting(f.pointer, element ? "[" + number + "]" : number);
    };
    const auto expect_accepted = [&](long double x, const char* why) {
      if (const auto e = error_of(text_of(x)))
        ADD_FAILURE() << where << ": " << text_of(x) << " (" << why << " of " << range->text()
                      << ") is refused: " << e->what();
    };
    const auto expect_refused = [&](long double x, const char* why) {
      const auto e = error_of(text_of(x));
      if (!e) ADD_FAILURE() << where << ": " << text_of(x) << " (" << why << " of " << range->text() << ") is accepted";
      else EXPECT_EQ(e->field(), field) << where << ": " << text_of(x) << " is refused elsewhere: " << e->what();
    };
    // The neighbouring value outside (direction -1) or inside (+1) a bound.
    const auto step = [&](long double bound, int outward) -> long double {
      if (integer) return bound + outward;
      return std::nextafter(static_cast<double>(bound), outward * INFINITY);
    };
    if (range->lo) {
      const long double lo = range->lo->value;
      if (range->lo->open) {
        expect_refused(lo, "the open lower bound");
        expect_accepted(step(lo, +1), "just inside the open lower bound");
      } else {
        expect_accepted(lo, "the closed lower bound");
        expect_refused(step(lo, -1), "just below the closed lower bound");
      }
    }
    if (range->hi) {
      const long double hi = range->hi->value;
      if (range->hi->open) {
        expect_refused(hi, "the open upper bound");
        expect_accepted(step(hi, -1), "just inside the open upper bound");
      } else {
        expect_accepted(hi, "the closed upper bound");
        expect_refused(step(hi, +1), "just above the closed upper bound");
      }
    }
    if (range->zero_too) expect_accepted(0, "0, allowed besides the interval");
  }
}

// The range a wire comment writes: between the '#' and the first ';'.
std::optional<DocRange> wire_range(const WireField& f) { return range_in(f.comment.substr(0, f.comment.find(';'))); }

TEST(SceneSchema, WireRangeCommentsAreTheDocumentedRanges) {
  std::map<std::string, DocField> documented;
  for (const DocField& f : doc_fields()) documented[f.pointer] = f;
  for (const WireField& w : wire_fields()) {
    const auto doc = documented.find(w.pointer);
    if (doc == documented.end() || !is_numeric(doc->second)) continue;
    // The wire's seed is a UInt32: its range is the type's, narrower than the file's.
    if (w.pointer == "/body/distribution/seed") continue;
    const std::optional<DocRange> wire = wire_range(w), file = range_in(doc->second.allowed);
    const std::string where = kCapnp + ":" + std::to_string(w.line) + ": " + w.pointer;
    if (!wire) {
      ADD_FAILURE() << where << ": the comment \"" << w.comment << "\" writes no range (before its first ';'); "
                    << kDocs << " writes " << doc->second.allowed;
      continue;
    }
    if (!file) continue;  // reported by DocumentedRangesAreTheReadersRanges
    EXPECT_TRUE(*wire == *file) << where << ": the comment's range " << wire->text() << " is not " << kDocs << ":"
                                << doc->second.line << "'s " << file->text();
  }
}

// A list the wire leaves null takes the file default; the comments that write it ("null = [...]") are right.
TEST(SceneSchema, WireNullCommentsAreTheFileDefaults) {
  const Scene defaults = parse("{}");
  const std::regex null_value(R"(null = (\[[^\]]*\]))");
  for (const WireField& w : wire_fields()) {
    std::smatch m;
    if (!std::regex_search(w.comment, m, null_value)) continue;
    const std::string where = kCapnp + ":" + std::to_string(w.line) + ": " + w.pointer;
    const std::string text = scene_setting(w.pointer, m[1]);
    try {
      expect_same(defaults, parse(text), where + ": the comment's default " + std::string(m[1]) +
                                             " is not the file's. Scene from " + text + " against parse_scene(\"{}\"):");
    } catch (const SceneError& e) {
      ADD_FAILURE() << where << ": the comment's default " << m[1] << " is refused: " << e.what();
    }
  }
}

// ---------------------------------------------------------------------------
// Names: the documented names of every enumerated field are the reader's and the wire's.

// The names the docs allow for `f`: the allowed cell's quoted code spans, or the face table.
std::vector<std::string> documented_names(const DocField& f) {
  std::vector<std::string> names;
  if (f.pointer == "/fixed") {
    const std::vector<std::string> lines = lines_of(read_text(kDocs));
    auto row = std::find(lines.begin(), lines.end(), "| name | face |");
    if (row == lines.end()) return names;
    for (row += 2; row != lines.end() && row->rfind("|", 0) == 0; ++row)
      for (const std::string& name : code_spans(cells_of(*row)[0])) names.push_back(name);
    return names;
  }
  if (f.type != "string") return names;
  for (const std::string& span : code_spans(f.allowed))
    if (span.size() >= 2 && span.front() == '"' && span.back() == '"') names.push_back(span.substr(1, span.size() - 2));
  return names;
}

TEST(SceneSchema, DocumentedNamesAreTheReadersAndTheWires) {
  int enumerated = 0;
  for (const DocField& f : doc_fields()) {
    const std::vector<std::string> names = documented_names(f);
    if (names.empty()) continue;
    ++enumerated;
    const bool list = f.pointer == "/fixed";
    const auto value = [&](const std::string& name) { return list ? "[\"" + name + "\"]" : "\"" + name + "\""; };
    const std::string where = kDocs + ":" + std::to_string(f.line) + ": " + f.pointer;

    // The reader's names, from its message for an unknown one.
    const auto e = error_of(scene_setting(f.pointer, value("no_such_name")));
    if (!e) {
      ADD_FAILURE() << where << ": an unknown name is accepted";
      continue;
    }
    const std::string known = "(known: ";
    const std::size_t at = e->reason().find(known);
    ASSERT_NE(at, std::string::npos) << where << ": " << e->what();
    std::vector<std::string> reader_names;
    std::istringstream list_text(e->reason().substr(at + known.size(), e->reason().size() - at - known.size() - 1));
    for (std::string name; std::getline(list_text, name, ',');) reader_names.push_back(name.substr(name.find_first_not_of(' ')));
    EXPECT_EQ(names, reader_names) << where << ": the documented names are not the reader's (in its order)";

    // The wire carries each name and gives it back.
    for (const std::string& name : names) {
      capnp::MallocMessageBuilder message;
      auto scene = message.initRoot<wire::Scene>();
      try {
        scene_json_to_wire(scene_setting(f.pointer, value(name)), kTestSource, scene);
      } catch (const SceneError& e) {
        ADD_FAILURE() << where << ": the wire has no name '" << name << "': " << e.what();
        continue;
      }
      const json back = json_with_defaults(scene);
      EXPECT_EQ(back[json::json_pointer(f.pointer)], json::parse(value(name))) << where << ": '" << name << "' on the wire";
    }
  }
  EXPECT_GE(enumerated, 10);
}

}  // namespace
}  // namespace palpate
