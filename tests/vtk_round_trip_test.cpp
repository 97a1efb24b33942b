// The ParaView export (core/vtk_writer.h) read back by a small VTK XML reader written here,
// independent of the writer: a model's state written and every point, cell and field compared
// with what was written (ascii and base64 binary); the sphere; the collection; refusals. Then
// the programs: palpate-verify --vtk, and palpate-client --headless --vtk against a real
// server, whose files are checked against the rows the same run writes as CSV and against
// the model rebuilt here.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "cli/child_process.h"
#include "core/model.h"
#include "core/node_cloud.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/stress.h"
#include "core/vtk_writer.h"
#include "tests/test_server.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace palpate {
namespace {

using cli::ProgramResult;
using cli::run_program;

// ---------------------------------------------------------------------------
// A small reader of VTK XML files: elements, attributes, DataArray contents (ascii, or binary
// = base64 of [header_type byte count][values]). Only what the tests need.

struct Array {
  std::string type, name, format;
  int components = 1;
  std::vector<double> values;
};

struct VtuFile {
  std::map<std::string, std::string> root;  // VTKFile attributes
  long points = -1, cells = -1;             // Piece NumberOfPoints / NumberOfCells
  std::map<std::string, Array> point_data, field_data;
  Array positions, connectivity, offsets, types;
};

std::string read_text(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + file.string());
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::map<std::string, std::string> attributes(const std::string& tag) {
  std::map<std::string, std::string> out;
  size_t at = tag.find(' ');
  while (at != std::string::npos) {
    const size_t eq = tag.find('=', at);
    if (eq == std::string::npos) break;
    std::string key = tag.substr(at, eq - at);
    key.erase(0, key.find_first_not_of(" \n\t"));
    const size_t open = tag.find('"', eq);
    const size_t close = tag.find('"', open + 1);
    if (open == std::string::npos || close == std::string::npos) throw std::runtime_error("bad attribute in " + tag);
    out[key] = tag.substr(open + 1, close - open - 1);
    at = close + 1;
    if (at >= tag.size() || tag.find('=', at) == std::string::npos) break;
  }
  return out;
}

template <class T>
void append_binary(const std::vector<uint8_t>& raw, size_t header, std::vector<double>& out) {
  uint64_t bytes = 0;
  std::memcpy(&bytes, raw.data(), header);
  if (raw.size() < header + bytes) throw std::runtime_error("binary array shorter than its header says");
  if (bytes % sizeof(T) != 0) throw std::runtime_error("binary array not a whole number of values");
  for (size_t k = 0; k < bytes / sizeof(T); ++k) {
    T v;
    std::memcpy(&v, raw.data() + header + k * sizeof(T), sizeof(T));
    out.push_back(static_cast<double>(v));
  }
}

Array parse_array(const std::string& tag, const std::string& body, size_t header) {
  const auto a = attributes(tag);
  Array r;
  r.type = a.at("type");
  r.name = a.count("Name") ? a.at("Name") : "";
  r.format = a.at("format");
  r.components = a.count("NumberOfComponents") ? std::stoi(a.at("NumberOfComponents")) : 1;
  if (r.format == "ascii") {
    std::istringstream in(body);
    double v;
    while (in >> v) r.values.push_back(v);
  } else if (r.format == "binary") {
    const std::vector<uint8_t> raw = vtk::base64_decode(body);
    if (r.type == "Float64") append_binary<double>(raw, header, r.values);
    else if (r.type == "Float32") append_binary<float>(raw, header, r.values);
    else if (r.type == "Int64") append_binary<int64_t>(raw, header, r.values);
    else if (r.type == "UInt8") append_binary<uint8_t>(raw, header, r.values);
    else throw std::runtime_error("type " + r.type + " not read here");
  } else {
    throw std::runtime_error("format " + r.format + " not read here");
  }
  if (a.count("NumberOfTuples") && std::stol(a.at("NumberOfTuples")) * r.components != static_cast<long>(r.values.size()))
    throw std::runtime_error("array " + r.name + ": NumberOfTuples disagrees with its values");
  return r;
}

VtuFile read_vtu(const fs::path& file) {
  const std::string text = read_text(file);
  VtuFile f;
  std::vector<std::string> open;  // element stack
  size_t header = 4;
  size_t at = 0;
  while ((at = text.find('<', at)) != std::string::npos) {
    const size_t end = text.find('>', at);
    if (end == std::string::npos) throw std::runtime_error(file.string() + ": unterminated tag");
    std::string tag = text.substr(at + 1, end - at - 1);
    at = end + 1;
    if (tag.empty() || tag[0] == '?' || tag[0] == '!') continue;
    if (tag[0] == '/') {
      if (open.empty() || open.back() != tag.substr(1)) throw std::runtime_error(file.string() + ": mismatched </" + tag);
      open.pop_back();
      continue;
    }
    const bool self_closing = tag.back() == '/';
    if (self_closing) tag.pop_back();
    const std::string name = tag.substr(0, tag.find(' '));
    if (name == "VTKFile") {
      f.root = attributes(tag);
      header = f.root.count("header_type") && f.root["header_type"] == "UInt64" ? 8 : 4;
    } else if (name == "Piece") {
      const auto a = attributes(tag);
      f.points = std::stol(a.at("NumberOfPoints"));
      f.cells = std::stol(a.at("NumberOfCells"));
    } else if (name == "DataArray") {
      const size_t close = text.find("</DataArray>", at);
      if (close == std::string::npos) throw std::runtime_error(file.string() + ": unterminated DataArray");
      Array a = parse_array(tag, text.substr(at, close - at), header);
      at = close + std::strlen("</DataArray>");
      const std::string section = open.empty() ? "" : open.back();
      if (section == "PointData") f.point_data[a.name] = a;
      else if (section == "FieldData") f.field_data[a.name] = a;
      else if (section == "Points") f.positions = a;
      else if (section == "Cells" && a.name == "connectivity") f.connectivity = a;
      else if (section == "Cells" && a.name == "offsets") f.offsets = a;
      else if (section == "Cells" && a.name == "types") f.types = a;
      else throw std::runtime_error(file.string() + ": DataArray " + a.name + " in <" + section + ">");
      continue;
    }
    if (!self_closing) open.push_back(name);
  }
  if (!open.empty()) throw std::runtime_error(file.string() + ": <" + open.back() + "> not closed");
  return f;
}

struct PvdEntry {
  double time;
  int part;
  std::string file;
};

std::vector<PvdEntry> read_pvd(const fs::path& file) {
  const std::string text = read_text(file);
  std::vector<PvdEntry> out;
  size_t at = 0;
  while ((at = text.find("<DataSet", at)) != std::string::npos) {
    const size_t end = text.find("/>", at);
    const auto a = attributes(text.substr(at, end - at));
    out.push_back({std::stod(a.at("timestep")), std::stoi(a.at("part")), a.at("file")});
    at = end;
  }
  return out;
}

// ---------------------------------------------------------------------------

const fs::path kData = fs::path(PALPATE_SOURCE_DIR) / "tests" / "data";

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("palpate_vtk_" + name + "_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// A deformed state of the model with a few contacts and a tool.
State deformed_state(const Model& m) {
  State s = make_state(m, Options{});
  for (int i = 0; i < m.particle_count; ++i) {
    const Vec3 X = m.rest_position.col(i);
    s.position.col(i) = X + Vec3(0.01 * X[2] * X[1], -0.02 * X[0], 0.015 * X[0] * X[2] + 0.003 * std::sin(3 * X[1]));
  }
  s.contact_index = {1, 5, m.particle_count - 1};
  for (size_t c = 0; c < s.contact_index.size(); ++c) s.contact_force.col(c) = Vec3(0.1 * c, -0.2, 1.5 + c);
  s.indenter_center = Vec3(0.5, 0.4, 1.3);
  s.indenter_contact_force = Vec3(-0.1, 0.6, -4.5);
  s.force_command = Vec3(0, 0, -4.5);
  s.time = 0.125;
  s.tick = 125;
  return s;
}

void expect_field(const VtuFile& f, const std::string& name, const std::vector<double>& expected) {
  ASSERT_TRUE(f.field_data.count(name)) << "field data " << name;
  const Array& a = f.field_data.at(name);
  ASSERT_EQ(a.values.size(), expected.size()) << name;
  for (size_t k = 0; k < expected.size(); ++k) EXPECT_EQ(a.values[k], expected[k]) << name << " " << k;
}

// Every point, cell and field of the file against the model and the state it was written from.
void expect_state_file(const VtuFile& f, const Model& m, const NodeCloud& cloud, const State& s, int cell_type) {
  const int n = m.particle_count;
  EXPECT_EQ(f.root.at("type"), "UnstructuredGrid");
  ASSERT_EQ(f.points, n);
  ASSERT_EQ(f.positions.components, 3);
  ASSERT_EQ(f.positions.values.size(), 3 * static_cast<size_t>(n));
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(f.positions.values[3 * i + k], s.position(k, i)) << "point " << i;

  // Cells: the cloud's, in its order.
  std::vector<std::vector<int>> cells;
  if (cell_type == 10)
    for (const auto& t : cloud.tetrahedra) cells.push_back({t[0], t[1], t[2], t[3]});
  else if (cell_type == 1)
    for (int i = 0; i < n; ++i) cells.push_back({i});
  if (cell_type != 12) {
    ASSERT_EQ(static_cast<size_t>(f.cells), cells.size());
  }
  ASSERT_EQ(f.types.values.size(), static_cast<size_t>(f.cells));
  ASSERT_EQ(f.offsets.values.size(), static_cast<size_t>(f.cells));
  const int per_cell = cell_type == 10 ? 4 : cell_type == 12 ? 8 : 1;
  ASSERT_EQ(f.connectivity.values.size(), static_cast<size_t>(f.cells) * per_cell);
  for (long c = 0; c < f.cells; ++c) {
    EXPECT_EQ(f.types.values[c], cell_type);
    EXPECT_EQ(f.offsets.values[c], (c + 1) * per_cell);
    if (cell_type != 12) {
      for (int k = 0; k < per_cell; ++k) EXPECT_EQ(f.connectivity.values[c * per_cell + k], cells[c][k]);
    }
  }
  if (cell_type == 12) {
    // Bricks of the lattice: each an axis-aligned box of the rest positions, nodes in VTK order
    // (bottom face counterclockwise from the min corner, then the top face).
    const Eigen::Vector3i sz = cloud.lattice_size;
    EXPECT_EQ(f.cells, static_cast<long>(sz[0] - 1) * (sz[1] - 1) * (sz[2] - 1));
    const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    for (long c = 0; c < f.cells; ++c) {
      const Vec3 lo = m.rest_position.col(static_cast<int>(f.connectivity.values[8 * c]));
      const Vec3 hi = m.rest_position.col(static_cast<int>(f.connectivity.values[8 * c + 6]));
      for (int k = 0; k < 8; ++k) {
        const Vec3 X = m.rest_position.col(static_cast<int>(f.connectivity.values[8 * c + k]));
        for (int d = 0; d < 3; ++d) EXPECT_EQ(X[d], corner[k][d] ? hi[d] : lo[d]) << "cell " << c << " node " << k;
      }
      EXPECT_TRUE((hi - lo).minCoeff() > 0) << "cell " << c;
    }
  }

  // Point data.
  for (const char* name : {"displacement", "displacement_magnitude", "von_mises", "contact_force"})
    ASSERT_TRUE(f.point_data.count(name)) << name;
  const Array& u = f.point_data.at("displacement");
  const Array& umag = f.point_data.at("displacement_magnitude");
  const Array& vm = f.point_data.at("von_mises");
  const Array& contact = f.point_data.at("contact_force");
  EXPECT_EQ(u.components, 3);
  EXPECT_EQ(umag.components, 1);
  EXPECT_EQ(contact.components, 3);
  std::vector<double> vm_expected;
  von_mises_stress(m, s.position, vm_expected);
  double vm_peak = 0;
  for (int i = 0; i < n; ++i) {
    const Vec3 d = s.position.col(i) - m.rest_position.col(i);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(u.values[3 * i + k], d[k]) << "particle " << i;
    EXPECT_EQ(umag.values[i], d.norm()) << "particle " << i;
    EXPECT_EQ(vm.values[i], vm_expected[i]) << "particle " << i;
    vm_peak = std::max(vm_peak, vm.values[i]);
  }
  EXPECT_GT(vm_peak, 0.0);  // the state is strained
  for (int i = 0; i < n; ++i) {
    Vec3 expected = Vec3::Zero();
    for (size_t c = 0; c < s.contact_index.size(); ++c)
      if (s.contact_index[c] == i) expected = s.contact_force.col(c);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(contact.values[3 * i + k], expected[k]) << "particle " << i;
  }
  expect_field(f, "time", {s.time});
  expect_field(f, "tick", {static_cast<double>(s.tick)});
  expect_field(f, "tool_position", {s.indenter_center[0], s.indenter_center[1], s.indenter_center[2]});
  expect_field(f, "tool_contact_force",
               {s.indenter_contact_force[0], s.indenter_contact_force[1], s.indenter_contact_force[2]});
  expect_field(f, "force_command", {s.force_command[0], s.force_command[1], s.force_command[2]});
}

void round_trip(const std::string& json, const fs::path& base, int cell_type) {
  const Scene scene = parse_scene(json, "inline-test-scene", base);
  const Model m = build_model(scene);
  const NodeCloud cloud = make_node_cloud(scene);
  vtk::UnstructuredGrid cells;
  cells.points.assign(3 * static_cast<size_t>(m.particle_count), 0.0);
  vtk::add_cloud_cells(cells, cloud);
  const State s = deformed_state(m);
  const fs::path dir = fresh_dir("round_trip");
  for (const vtk::Encoding e : {vtk::Encoding::ascii, vtk::Encoding::binary}) {
    SCOPED_TRACE(e == vtk::Encoding::ascii ? "ascii" : "binary");
    const fs::path file = dir / "state.vtu";
    vtk::write_vtu(file, vtk::body_state_grid(cells, m, s), e);
    const VtuFile f = read_vtu(file);
    EXPECT_EQ(f.positions.format, e == vtk::Encoding::ascii ? "ascii" : "binary");
    EXPECT_EQ(f.positions.type, "Float64");
    expect_state_file(f, m, cloud, s, cell_type);
  }
  fs::remove_all(dir);
}

TEST(VtkRoundTrip, TetrahedralMeshBody) {
  round_trip(R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]},
                 "distribution": {"type": "mesh", "file": "cube_tet_small.msh"}}, "mls": {"volumes": "mesh"}})",
             kData, 10);
}

TEST(VtkRoundTrip, LatticeBodyAsHexahedra) {
  round_trip(R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 2]}, "distribution": {"type": "grid", "per_edge": 4}},
                 "mls": {"neighbors": 16}})",
             kData, 12);
  round_trip(R"({"model": "hex_fem", "body": {"box": {"min": [0, 0, 0], "max": [1, 1, 2]},
                 "distribution": {"type": "grid", "per_edge": 4}}})",
             kData, 12);
}

TEST(VtkRoundTrip, NodeListAsVertices) {
  const fs::path dir = fresh_dir("nodes");
  std::ofstream nodes(dir / "nodes.txt");
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 5; ++j)
      for (int k = 0; k < 5; ++k) nodes << 0.25 * i + 0.01 * ((i * 7 + j * 3 + k) % 5) << ' ' << 0.25 * j << ' ' << 0.25 * k << '\n';
  nodes.close();
  round_trip(R"({"body": {"box": {"min": [0, 0, 0], "max": [1.04, 1, 1]}, "distribution": {"type": "node_file", "node_file": "nodes.txt"}},
                 "mls": {"neighbors": 16}, "fixed": []})",
             dir, 1);
  fs::remove_all(dir);
}

TEST(VtkRoundTrip, SphereSurfaceAndCollection) {
  const Vec3 centre(0.1, -0.2, 0.7);
  const vtk::UnstructuredGrid g = vtk::sphere_surface(centre, 0.5, 2);
  ASSERT_EQ(g.point_count(), 10 * 16 + 2);
  ASSERT_EQ(g.types.size(), 20u * 16);
  for (int64_t i = 0; i < g.point_count(); ++i)
    EXPECT_NEAR((Vec3(g.points[3 * i], g.points[3 * i + 1], g.points[3 * i + 2]) - centre).norm(), 0.5, 1e-12);
  for (size_t c = 0; c < g.types.size(); ++c) {  // counterclockwise seen from outside
    Vec3 p[3];
    for (int k = 0; k < 3; ++k) {
      const int64_t i = g.connectivity[3 * c + k];
      p[k] = Vec3(g.points[3 * i], g.points[3 * i + 1], g.points[3 * i + 2]);
    }
    EXPECT_GT((p[1] - p[0]).cross(p[2] - p[0]).dot((p[0] + p[1] + p[2]) / 3 - centre), 0.0) << "triangle " << c;
  }
  const fs::path dir = fresh_dir("sphere");
  vtk::write_vtu(dir / "tool.vtu", g, vtk::Encoding::binary);
  const VtuFile f = read_vtu(dir / "tool.vtu");
  ASSERT_EQ(f.positions.values.size(), g.points.size());
  for (size_t k = 0; k < g.points.size(); ++k) EXPECT_EQ(f.positions.values[k], g.points[k]);
  for (size_t k = 0; k < g.connectivity.size(); ++k) EXPECT_EQ(f.connectivity.values[k], g.connectivity[k]);
  EXPECT_EQ(f.types.values.front(), 5);
  ASSERT_TRUE(f.point_data.count("Normals"));

  vtk::write_pvd(dir / "series.pvd", {{0.0, 0, "a.vtu"}, {0.0, 1, "b.vtu"}, {2.5, 0, "c.vtu"}});
  const auto entries = read_pvd(dir / "series.pvd");
  ASSERT_EQ(entries.size(), 3u);
  EXPECT_EQ(entries[1].part, 1);
  EXPECT_EQ(entries[2].time, 2.5);
  EXPECT_EQ(entries[2].file, "c.vtu");
  fs::remove_all(dir);
}

TEST(VtkRoundTrip, Base64AgainstKnownText) {
  // RFC 4648's examples, and every length modulo 3.
  const std::string plain = "foobar";
  const char* expected[] = {"", "Zg==", "Zm8=", "Zm9v", "Zm9vYg==", "Zm9vYmE=", "Zm9vYmFy"};
  for (size_t k = 0; k <= plain.size(); ++k) {
    EXPECT_EQ(vtk::base64_encode(reinterpret_cast<const uint8_t*>(plain.data()), k), expected[k]);
    const auto back = vtk::base64_decode(expected[k]);
    EXPECT_EQ(std::string(back.begin(), back.end()), plain.substr(0, k));
  }
  EXPECT_THROW(vtk::base64_decode("Zm9v!"), std::runtime_error);
}

TEST(VtkRoundTrip, InconsistentGridsAreRefusedNamingTheFile) {
  const fs::path dir = fresh_dir("refusals");
  vtk::UnstructuredGrid g;
  g.points = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  vtk::add_cells(g, vtk::CellType::triangle, {0, 1, 2});
  auto message = [&](const vtk::UnstructuredGrid& grid) {
    try {
      vtk::write_vtu(dir / "bad.vtu", grid, vtk::Encoding::ascii);
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  vtk::UnstructuredGrid bad = g;
  bad.connectivity[2] = 3;
  EXPECT_NE(message(bad).find("bad.vtu: cell connectivity 2: point 3 out of range (3 points)"), std::string::npos)
      << message(bad);
  bad = g;
  bad.point_data.push_back({"u", 3, {1, 2, 3}});
  EXPECT_NE(message(bad).find("point data 'u': 1 tuples for 3 points"), std::string::npos) << message(bad);
  bad = g;
  bad.point_data.push_back({"s", 1, {1, NAN, 3}});
  EXPECT_NE(message(bad).find("'s': value 1 is not finite"), std::string::npos) << message(bad);
  bad = g;
  bad.field_data.push_back({"a\"b", 1, {1}});
  EXPECT_NE(message(bad).find("no quotes"), std::string::npos) << message(bad);
  EXPECT_FALSE(fs::exists(dir / "bad.vtu"));
  EXPECT_EQ(message(g), "accepted");
  fs::remove_all(dir);
}

// ---------------------------------------------------------------------------
// The programs.

std::vector<std::vector<std::string>> read_csv(const fs::path& file) {
  std::ifstream in(file);
  std::vector<std::vector<std::string>> rows;
  std::string line;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    rows.push_back(cells);
  }
  return rows;
}

TEST(VtkPrograms, VerifyWritesOneBodyAndToolPerForce) {
  const fs::path dir = fresh_dir("verify");
  const ProgramResult r = run_program({PALPATE_VERIFY_BIN, "--scene", PALPATE_SOURCE_DIR "/scenes/hertz_cube.json",
                                       "--per-edge", "8", "--forces", "20,40", "--reference", "none", "--quiet",
                                       "--vtk", (dir / "out").string()},
                                      std::chrono::seconds(300));
  ASSERT_EQ(r.status, 0) << r.err;
  const auto entries = read_pvd(dir / "out" / "verify.pvd");
  ASSERT_EQ(entries.size(), 4u);
  const Scene scene = load_scene(PALPATE_SOURCE_DIR "/scenes/hertz_cube.json", {{"body.distribution.per_edge", "8"}});
  const Model m = build_model(scene);
  for (int k = 0; k < 2; ++k) {
    SCOPED_TRACE("force " + std::to_string(k));
    EXPECT_EQ(entries[2 * k].time, k);
    EXPECT_EQ(entries[2 * k].part, 0);
    EXPECT_EQ(entries[2 * k + 1].part, 1);
    const VtuFile body = read_vtu(dir / "out" / entries[2 * k].file);
    const VtuFile tool = read_vtu(dir / "out" / entries[2 * k + 1].file);
    expect_field(body, "force_n", {k == 0 ? 20.0 : 40.0});
    ASSERT_EQ(body.points, m.particle_count);
    EXPECT_EQ(body.types.values.front(), 12);  // the lattice's bricks
    // At rest under the force: the contact forces on the particles balance the command.
    const Array& contact = body.point_data.at("contact_force");
    double sum_z = 0;
    for (int i = 0; i < m.particle_count; ++i) sum_z += contact.values[3 * i + 2];
    EXPECT_NEAR(sum_z, k == 0 ? -20.0 : -40.0, 0.05) << "the tool presses down on the body";
    EXPECT_NEAR(body.field_data.at("tool_contact_force").values[2], -sum_z, 1e-9);
    // The stored fields are those of the stored points.
    Points x(3, m.particle_count);
    for (int i = 0; i < m.particle_count; ++i)
      for (int d = 0; d < 3; ++d) x(d, i) = body.positions.values[3 * i + d];
    std::vector<double> vm;
    von_mises_stress(m, x, vm);
    for (int i = 0; i < m.particle_count; ++i) {
      EXPECT_NEAR(body.point_data.at("von_mises").values[i], vm[i], 1e-9 * (1 + vm[i])) << "particle " << i;
      EXPECT_EQ(body.point_data.at("displacement").values[3 * i + 2], x(2, i) - m.rest_position(2, i));
    }
    // The sphere is the tool at its position.
    const auto& c = body.field_data.at("tool_position").values;
    EXPECT_EQ(tool.field_data.at("tool_position").values, c);
    for (long p = 0; p < tool.points; ++p)
      EXPECT_NEAR((Vec3(tool.positions.values[3 * p], tool.positions.values[3 * p + 1], tool.positions.values[3 * p + 2]) -
                   Vec3(c[0], c[1], c[2]))
                      .norm(),
                  m.indenter_radius, 1e-12);
  }
  fs::remove_all(dir);
}

TEST(VtkPrograms, TheClientWritesFilesOfHeadlessRowsOnly) {
  const ProgramResult realtime = run_program({PALPATE_CLIENT_BIN, "--vtk", "out"}, std::chrono::seconds(20));
  EXPECT_EQ(realtime.status, 2);
  EXPECT_NE(realtime.err.find("palpate-client: --vtk: writes the rows of --headless (add --headless)"), std::string::npos)
      << realtime.err;
  const ProgramResult surface = run_program({PALPATE_CLIENT_BIN, "--headless", "--vtk-surface"}, std::chrono::seconds(20));
  EXPECT_EQ(surface.status, 2);
  EXPECT_NE(surface.err.find("--vtk-surface, --vtk-ascii: only with --vtk DIR"), std::string::npos) << surface.err;
  const ProgramResult help = run_program({PALPATE_VERIFY_BIN, "--help"}, std::chrono::seconds(20));
  EXPECT_NE(help.out.find("--vtk DIR"), std::string::npos) << help.out;
}

// One scene: a full and a surface-only run of palpate-client --headless --vtk on the same
// server, checked against the CSV of the full run and the model rebuilt here.
void expect_client_files(const std::string& scene_name, const SceneOverrides& overrides) {
  const test::ServerProcess server(std::vector<std::string>{});  // palpate-server, TCP only (tests/test_server.h)
  ASSERT_FALSE(server.address().empty()) << "the server did not start";
  const fs::path dir = fresh_dir("client");
  std::vector<std::string> common = {PALPATE_CLIENT_BIN, "--connect", server.address(), "--scene", scene_name,
                                     "--headless", "--forces", "10.36,29.3", "--max-steps", "1500"};
  for (const auto& [key, value] : overrides) common.insert(common.end(), {"--set", key + "=" + value});
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = common;
    args.insert(args.end(), extra.begin(), extra.end());
    return args;
  };
  const ProgramResult full =
      run_program(with({"--vtk", (dir / "full").string(), "--csv", (dir / "full.csv").string()}), std::chrono::seconds(300));
  ASSERT_EQ(full.status, 0) << full.err;
  const ProgramResult surface = run_program(
      with({"--vtk", (dir / "surface").string(), "--vtk-surface", "--vtk-ascii"}), std::chrono::seconds(300));
  ASSERT_EQ(surface.status, 0) << surface.err;

  const auto csv = read_csv(dir / "full.csv");
  ASSERT_EQ(csv.size(), 3u);  // header + one row per force
  std::map<std::string, size_t> column;
  for (size_t k = 0; k < csv[0].size(); ++k) column[csv[0][k]] = k;
  const auto entries = read_pvd(dir / "full" / "client.pvd");
  ASSERT_EQ(entries.size(), 4u);

  const Scene scene = load_scene(PALPATE_SOURCE_DIR "/scenes/" + scene_name + ".json", overrides);
  const Model m = build_model(scene);
  std::set<int> surface_vertices;
  for (int k = 0; k < m.surface_triangles.size(); ++k) surface_vertices.insert(m.surface_triangles.data()[k]);

  for (size_t row = 0; row < 2; ++row) {
    SCOPED_TRACE("row " + std::to_string(row));
    const auto& line = csv[row + 1];
    auto number = [&](const std::string& name) { return std::stod(line.at(column.at(name))); };
    EXPECT_NEAR(entries[2 * row].time, number("time_s"), 1e-9 * (1 + number("time_s")));
    const VtuFile body = read_vtu(dir / "full" / entries[2 * row].file);
    // The scalars of the frame, as the CSV has them (9 significant digits there).
    auto close = [](double a, double b) { return std::abs(a - b) <= 1e-7 * (1 + std::abs(b)); };
    EXPECT_EQ(body.field_data.at("tick").values[0], number("tick"));
    const auto& c = body.field_data.at("tool_position").values;
    const auto& f = body.field_data.at("tool_contact_force").values;
    EXPECT_TRUE(close(c[0], number("tool_x_m")) && close(c[1], number("tool_y_m")) && close(c[2], number("tool_z_m")));
    EXPECT_TRUE(close(f[0], number("contact_fx_n")) && close(f[1], number("contact_fy_n")) &&
                close(f[2], number("contact_fz_n")));
    EXPECT_NEAR(f[2], number("force_command_n"), 0.02 * number("force_command_n")) << "at rest";

    // Points: every particle; cells: the surface triangles of the model.
    ASSERT_EQ(body.points, m.particle_count);
    ASSERT_EQ(body.cells, m.surface_triangles.cols());
    for (long t = 0; t < body.cells; ++t) {
      EXPECT_EQ(body.types.values[t], 5);
      for (int k = 0; k < 3; ++k) EXPECT_EQ(body.connectivity.values[3 * t + k], m.surface_triangles(k, t));
    }
    // The fields: displacement from the model's rest positions (Float32 on the wire), the
    // contact forces sum to the force on the tool, von Mises as core computes it from those points.
    Points x(3, m.particle_count);
    double sum[3] = {0, 0, 0};
    const Array& u = body.point_data.at("displacement");
    for (int i = 0; i < m.particle_count; ++i) {
      Vec3 d;
      for (int k = 0; k < 3; ++k) {
        x(k, i) = body.positions.values[3 * i + k];
        d[k] = u.values[3 * i + k];
        EXPECT_NEAR(x(k, i) - d[k], m.rest_position(k, i), 1e-6) << "particle " << i;
        sum[k] += body.point_data.at("contact_force").values[3 * i + k];
      }
      EXPECT_NEAR(body.point_data.at("displacement_magnitude").values[i], d.norm(), 1e-6) << "particle " << i;
    }
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(sum[k], -f[k], 1e-4 * (1 + std::abs(f[k])));
    std::vector<double> vm;
    von_mises_stress(m, x, vm);
    double peak = 0;
    for (double v : vm) peak = std::max(peak, v);
    EXPECT_GT(peak, 10.0);
    const Array& vm_file = body.point_data.at("von_mises");
    for (int i = 0; i < m.particle_count; ++i)
      EXPECT_NEAR(vm_file.values[i], vm[i], 1.0 + 2e-3 * peak) << "particle " << i;

    // The surface-only run (bit-identical headless stepping): the surface vertices, ascending,
    // with the same values; the triangles renumbered onto them.
    const auto surface_entries = read_pvd(dir / "surface" / "client.pvd");
    ASSERT_EQ(surface_entries.size(), 4u);
    const VtuFile part = read_vtu(dir / "surface" / surface_entries[2 * row].file);
    EXPECT_EQ(part.positions.format, "ascii");
    ASSERT_EQ(part.points, static_cast<long>(surface_vertices.size()));
    long p = 0;
    for (const int i : surface_vertices) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(part.positions.values[3 * p + k], body.positions.values[3 * i + k]);
      EXPECT_EQ(part.point_data.at("von_mises").values[p], vm_file.values[i]);
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(part.point_data.at("displacement").values[3 * p + k], u.values[3 * i + k]);
        EXPECT_EQ(part.point_data.at("contact_force").values[3 * p + k],
                  body.point_data.at("contact_force").values[3 * i + k]);
      }
      EXPECT_EQ(part.point_data.at("displacement_magnitude").values[p],
                body.point_data.at("displacement_magnitude").values[i]);
      ++p;
    }
    const std::vector<int> vertices(surface_vertices.begin(), surface_vertices.end());
    ASSERT_EQ(part.cells, body.cells);
    for (long k = 0; k < 3 * part.cells; ++k)
      EXPECT_EQ(vertices.at(static_cast<size_t>(part.connectivity.values[k])), body.connectivity.values[k]);
  }
  fs::remove_all(dir);
}

TEST(VtkPrograms, HeadlessClientWritesWhatItReceived) {
  // A gmsh mesh (its boundary nodes come first: the surface vertices are 0 ... 775) and a
  // lattice (the surface vertices interleave with the interior: their order matters).
  {
    SCOPED_TRACE("hertz_cube_haptic");
    expect_client_files("hertz_cube_haptic", {});
  }
  {
    SCOPED_TRACE("hertz_cube at 10^3");
    expect_client_files("hertz_cube", {{"body.distribution.per_edge", "10"}});
  }
}

}  // namespace
}  // namespace palpate
