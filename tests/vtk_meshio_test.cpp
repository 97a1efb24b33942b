// The ParaView export (core/vtk_writer.h) read by an independent reader: Debian's meshio
// (python3-meshio, through tests/vtk_meshio_read.py run by /usr/bin/python3), not the
// project's own reader of tests/vtk_round_trip_test.cpp. Each kind of cloud the writer
// knows (tetrahedral mesh, lattice as bricks, hex FEM lattice, node list as vertices) at a
// deformed state, ascii and binary, and the tool's sphere and a collection: the point count,
// every point, every cell's connectivity and every point- and field-data value that meshio
// finds are compared with what the model and the state hold, computed here. Both encodings
// are exact (vtk_writer.h: binary raw Float64, ascii 17 significant digits), so the values
// must agree bit for bit; the sphere's normals, recomputed here from the points, to 1e-12.
// A file with one value changed by a part in 10^9 must be caught (ACorruptedValueIsCaught).
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cli/child_process.h"
#include "core/model.h"
#include "core/node_cloud.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/stress.h"
#include "core/vtk_writer.h"

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace palpate {
namespace {

const fs::path kData = fs::path(PALPATE_SOURCE_DIR) / "tests" / "data";
const std::string kReader = PALPATE_SOURCE_DIR "/tests/vtk_meshio_read.py";

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("palpate_meshio_" + name + "_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// What meshio read from `files` (tests/vtk_meshio_read.py), keyed by file.
json read_with_meshio(const std::vector<fs::path>& files) {
  std::vector<std::string> args = {PALPATE_DEBIAN_PYTHON, kReader};
  for (const auto& f : files) args.push_back(f.string());
  const cli::ProgramResult r = cli::run_program(args, std::chrono::seconds(120));
  if (r.status != 0) throw std::runtime_error("meshio could not read the files (status " + std::to_string(r.status) + "): " + r.err);
  return json::parse(r.out);
}

// A named array as the C++ side knows it, and how close the file's must be.
struct Values {
  std::vector<double> values;
  double tolerance = 0.0;  // absolute; 0: bit for bit
};

// What a file must hold.
struct Expected {
  std::vector<double> points;                  // 3 per point
  std::string cell_type;                       // meshio's name of the one cell type written
  std::vector<std::vector<int64_t>> cells;     // each cell's points
  bool cells_in_order = true;                  // false: compared as a multiset (the writer's order is its own)
  std::map<std::string, Values> point_data, field_data;
};

// Compares two arrays value by value; appends a line per disagreeing array (the first index,
// the count and the largest difference) to `out`, and returns the largest difference.
double compare(const std::string& what, const std::vector<double>& file, const Values& expected,
               std::vector<std::string>& out) {
  if (file.size() != expected.values.size()) {
    out.push_back(what + ": " + std::to_string(file.size()) + " values read, " + std::to_string(expected.values.size()) +
                  " expected");
    return INFINITY;
  }
  double largest = 0;
  long wrong = 0, first = -1;
  for (size_t k = 0; k < file.size(); ++k) {
    const double d = std::abs(file[k] - expected.values[k]);
    largest = std::max(largest, d);
    if (!(d <= expected.tolerance)) {
      ++wrong;
      if (first < 0) first = static_cast<long>(k);
    }
  }
  if (wrong > 0) {
    std::ostringstream s;
    s.precision(17);
    s << what << ": " << wrong << " of " << file.size() << " values differ, the first at " << first << " (read "
      << file[first] << ", expected " << expected.values[first] << "), largest difference " << largest;
    out.push_back(s.str());
  }
  return largest;
}

// Every disagreement between what meshio read of a .vtu and `e` (empty: the file is right).
std::vector<std::string> differences(const json& read, const Expected& e) {
  std::vector<std::string> out;
  const long n = static_cast<long>(e.points.size() / 3);
  if (read.at("point_count").get<long>() != n)
    out.push_back("point count " + std::to_string(read.at("point_count").get<long>()) + ", expected " + std::to_string(n));
  compare("points", read.at("points").get<std::vector<double>>(), {e.points, 0.0}, out);

  const json& blocks = read.at("cells");
  if (blocks.size() != 1) {
    out.push_back(std::to_string(blocks.size()) + " cell blocks, expected one of " + e.cell_type);
  } else {
    const json& block = blocks[0];
    if (block.at("type") != e.cell_type) out.push_back("cell type " + block.at("type").get<std::string>() + ", expected " + e.cell_type);
    const auto flat = block.at("connectivity").get<std::vector<int64_t>>();
    const size_t per_cell = e.cells.empty() ? 1 : e.cells[0].size();
    std::vector<std::vector<int64_t>> cells;
    for (size_t k = 0; k + per_cell <= flat.size(); k += per_cell) cells.emplace_back(flat.begin() + k, flat.begin() + k + per_cell);
    if (flat.size() != cells.size() * per_cell || cells.size() != e.cells.size()) {
      out.push_back(std::to_string(flat.size()) + " connectivity entries, expected " + std::to_string(e.cells.size()) +
                    " cells of " + std::to_string(per_cell));
    } else {
      std::vector<std::vector<int64_t>> expected = e.cells;
      if (!e.cells_in_order) {
        std::sort(cells.begin(), cells.end());
        std::sort(expected.begin(), expected.end());
      }
      long wrong = 0;
      for (size_t c = 0; c < cells.size(); ++c) wrong += cells[c] != expected[c];
      if (wrong > 0) out.push_back("connectivity: " + std::to_string(wrong) + " of " + std::to_string(cells.size()) + " cells differ");
    }
  }

  for (const auto& [section, expected] : {std::pair{"point_data", &e.point_data}, std::pair{"field_data", &e.field_data}}) {
    const json& arrays = read.at(section);
    for (const auto& [name, values] : *expected) {
      if (!arrays.contains(name)) {
        out.push_back(std::string(section) + " '" + name + "' not found");
        continue;
      }
      compare(std::string(section) + " '" + name + "'", arrays.at(name).at("values").get<std::vector<double>>(), values, out);
    }
    if (arrays.size() != expected->size())
      out.push_back(std::string(section) + ": " + std::to_string(arrays.size()) + " arrays read, " +
                    std::to_string(expected->size()) + " expected");
  }
  return out;
}

// A deformed state of the model with a few contacts and a tool (as in vtk_round_trip_test.cpp).
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

// What vtk::body_state_grid's file must hold for the model, its cloud and the state,
// computed from them here (vtk_writer.h documents the arrays).
Expected expected_state_file(const Model& m, const NodeCloud& cloud, const State& s) {
  const int n = m.particle_count;
  Expected e;
  e.points.assign(s.position.data(), s.position.data() + 3 * static_cast<size_t>(n));
  const Eigen::Vector3i sz = cloud.lattice_size;
  if (!cloud.tetrahedra.empty()) {
    e.cell_type = "tetra";
    for (const auto& t : cloud.tetrahedra) e.cells.push_back({t[0], t[1], t[2], t[3]});
  } else if (sz.minCoeff() >= 2 && static_cast<long>(sz[0]) * sz[1] * sz[2] == n) {
    // Every brick of the lattice once, its nodes in VTK_HEXAHEDRON's order: the lower face
    // counterclockwise seen from above from the brick's lowest corner, then the upper face.
    e.cell_type = "hexahedron";
    e.cells_in_order = false;
    auto node = [&](int a, int b, int c) { return a + static_cast<int64_t>(sz[0]) * (b + static_cast<int64_t>(sz[1]) * c); };
    const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    for (int a = 0; a + 1 < sz[0]; ++a)
      for (int b = 0; b + 1 < sz[1]; ++b)
        for (int c = 0; c + 1 < sz[2]; ++c) {
          std::vector<int64_t> brick;
          for (const auto& k : corner) brick.push_back(node(a + k[0], b + k[1], c + k[2]));
          e.cells.push_back(brick);
        }
  } else {
    e.cell_type = "vertex";
    for (int i = 0; i < n; ++i) e.cells.push_back({i});
  }
  Values u, umag, vm, contact;
  std::vector<double> von_mises;
  von_mises_stress(m, s.position, von_mises);
  contact.values.assign(3 * static_cast<size_t>(n), 0.0);
  for (size_t c = 0; c < s.contact_index.size(); ++c)
    for (int k = 0; k < 3; ++k) contact.values[3 * static_cast<size_t>(s.contact_index[c]) + k] = s.contact_force(k, c);
  for (int i = 0; i < n; ++i) {
    const Vec3 d = s.position.col(i) - m.rest_position.col(i);
    u.values.insert(u.values.end(), {d[0], d[1], d[2]});
    umag.values.push_back(d.norm());
  }
  vm.values = von_mises;
  e.point_data = {{"displacement", u}, {"displacement_magnitude", umag}, {"von_mises", vm}, {"contact_force", contact}};
  const Vec3 &c = s.indenter_center, &f = s.indenter_contact_force, &command = s.force_command;
  e.field_data = {{"time", {{s.time}}},
                  {"tick", {{static_cast<double>(s.tick)}}},
                  {"tool_position", {{c[0], c[1], c[2]}}},
                  {"tool_contact_force", {{f[0], f[1], f[2]}}},
                  {"force_command", {{command[0], command[1], command[2]}}}};
  return e;
}

struct Case {
  std::string name, scene_json;
  fs::path base;
  std::string cell_type;  // meshio's name, to be sure each kind is covered
};

// A state file of each kind of cloud, both encodings, all read in one meshio run.
TEST(VtkMeshio, StateFilesOfEveryCloudKindAgreeValueByValue) {
  const fs::path dir = fresh_dir("states");
  {
    std::ofstream nodes(dir / "nodes.txt");
    for (int i = 0; i < 5; ++i)
      for (int j = 0; j < 5; ++j)
        for (int k = 0; k < 5; ++k) nodes << 0.25 * i + 0.01 * ((i * 7 + j * 3 + k) % 5) << ' ' << 0.25 * j << ' ' << 0.25 * k << '\n';
  }
  const std::vector<Case> cases = {
      {"mesh",
       R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]},
           "distribution": {"type": "mesh", "file": "cube_tet_small.msh"}}, "mls": {"volumes": "mesh"}})",
       kData, "tetra"},
      {"lattice",
       R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 2]}, "distribution": {"type": "grid", "per_edge": 4}},
           "mls": {"neighbors": 16}})",
       kData, "hexahedron"},
      {"hex_fem",
       R"({"model": "hex_fem", "body": {"box": {"min": [0, 0, 0], "max": [1, 1, 2]},
           "distribution": {"type": "grid", "per_edge": 4}}})",
       kData, "hexahedron"},
      {"nodes",
       R"({"body": {"box": {"min": [0, 0, 0], "max": [1.04, 1, 1]}, "distribution": {"type": "node_file", "node_file": "nodes.txt"}},
           "mls": {"neighbors": 16}, "fixed": []})",
       dir, "vertex"},
  };
  std::vector<fs::path> files;
  std::vector<Expected> expected;
  for (const Case& c : cases) {
    const Scene scene = parse_scene(c.scene_json, "inline-test-scene", c.base);
    const Model m = build_model(scene);
    const NodeCloud cloud = make_node_cloud(scene);
    vtk::UnstructuredGrid cells;
    cells.points.assign(3 * static_cast<size_t>(m.particle_count), 0.0);
    vtk::add_cloud_cells(cells, cloud);
    const State s = deformed_state(m);
    Expected e = expected_state_file(m, cloud, s);
    ASSERT_EQ(e.cell_type, c.cell_type) << c.name;
    double vm_peak = 0;
    for (double v : e.point_data.at("von_mises").values) vm_peak = std::max(vm_peak, v);
    EXPECT_GT(vm_peak, 0.0) << c.name << ": the state is strained";
    for (const vtk::Encoding enc : {vtk::Encoding::ascii, vtk::Encoding::binary}) {
      files.push_back(dir / (c.name + (enc == vtk::Encoding::ascii ? "_ascii.vtu" : "_binary.vtu")));
      vtk::write_vtu(files.back(), vtk::body_state_grid(cells, m, s), enc);
      expected.push_back(e);
    }
  }
  const json read = read_with_meshio(files);
  for (size_t k = 0; k < files.size(); ++k) {
    SCOPED_TRACE(files[k].filename().string());
    const std::vector<std::string> diff = differences(read.at(files[k].string()), expected[k]);
    for (const std::string& d : diff) ADD_FAILURE() << d;
    std::printf("%-20s meshio: %ld points, %zu %s cells, %zu point-data and %zu field-data arrays: %s\n",
                files[k].filename().c_str(), read.at(files[k].string()).at("point_count").get<long>(),
                expected[k].cells.size(), expected[k].cell_type.c_str(), expected[k].point_data.size(),
                expected[k].field_data.size(), diff.empty() ? "every value bit for bit" : "DIFFERENT");
  }
  fs::remove_all(dir);
}

// The tool's sphere (triangles with normals) and a collection of two parts over two times.
TEST(VtkMeshio, SphereSurfaceAndCollection) {
  const fs::path dir = fresh_dir("sphere");
  const Vec3 centre(0.1, -0.2, 0.7);
  const double radius = 0.5;
  const vtk::UnstructuredGrid g = vtk::sphere_surface(centre, radius, 2);
  vtk::write_vtu(dir / "tool.vtu", g, vtk::Encoding::binary);
  vtk::write_pvd(dir / "series.pvd", {{0.0, 0, "body_0.vtu"}, {0.0, 1, "tool_0.vtu"}, {2.5, 0, "body_1.vtu"}});
  const json read = read_with_meshio({dir / "tool.vtu", dir / "series.pvd"});

  // The points are those written (10 4^2 + 2 of them, on the sphere), the triangles those
  // written (20 4^2), the normals the unit radial direction at each point.
  Expected e;
  e.points = g.points;
  e.cell_type = "triangle";
  for (size_t c = 0; c < g.types.size(); ++c)
    e.cells.push_back({g.connectivity[3 * c], g.connectivity[3 * c + 1], g.connectivity[3 * c + 2]});
  Values normals{{}, 1e-12};
  for (int64_t i = 0; i < g.point_count(); ++i) {
    const Vec3 p(g.points[3 * i], g.points[3 * i + 1], g.points[3 * i + 2]);
    EXPECT_NEAR((p - centre).norm(), radius, 1e-12) << "point " << i;
    const Vec3 nrm = (p - centre).normalized();
    normals.values.insert(normals.values.end(), {nrm[0], nrm[1], nrm[2]});
  }
  e.point_data = {{"Normals", normals}};
  const json& tool = read.at((dir / "tool.vtu").string());
  EXPECT_EQ(tool.at("point_count"), 162);
  EXPECT_EQ(e.cells.size(), 320u);
  for (const std::string& d : differences(tool, e)) ADD_FAILURE() << d;

  const json& series = read.at((dir / "series.pvd").string()).at("datasets");
  ASSERT_EQ(series.size(), 3u);
  EXPECT_EQ(series[0], json({{"timestep", 0.0}, {"part", 0}, {"file", "body_0.vtu"}}));
  EXPECT_EQ(series[1], json({{"timestep", 0.0}, {"part", 1}, {"file", "tool_0.vtu"}}));
  EXPECT_EQ(series[2], json({{"timestep", 2.5}, {"part", 0}, {"file", "body_1.vtu"}}));
  fs::remove_all(dir);
}

// The comparison has teeth: one von Mises value of an ascii file changed by a part in 10^9
// (far below what a plot would show, far above the file's 17 digits) is found, and only it.
TEST(VtkMeshio, ACorruptedValueIsCaught) {
  const fs::path dir = fresh_dir("corrupt");
  const Scene scene = parse_scene(
      R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 2]}, "distribution": {"type": "grid", "per_edge": 4}},
          "mls": {"neighbors": 16}})",
      "inline-test-scene", kData);
  const Model m = build_model(scene);
  const NodeCloud cloud = make_node_cloud(scene);
  vtk::UnstructuredGrid cells;
  cells.points.assign(3 * static_cast<size_t>(m.particle_count), 0.0);
  vtk::add_cloud_cells(cells, cloud);
  const State s = deformed_state(m);
  const fs::path file = dir / "state.vtu";
  vtk::write_vtu(file, vtk::body_state_grid(cells, m, s), vtk::Encoding::ascii);
  const Expected e = expected_state_file(m, cloud, s);
  ASSERT_TRUE(differences(read_with_meshio({file}).at(file.string()), e).empty());

  // The 8th von Mises value (particle 7), rewritten 1e-9 larger.
  std::string text;
  {
    std::ifstream in(file);
    std::stringstream ss;
    ss << in.rdbuf();
    text = ss.str();
  }
  size_t at = text.find('>', text.find("Name=\"von_mises\"")) + 1;
  for (int k = 0; k < 7; ++k) {
    at = text.find_first_not_of(" \n\t", at);
    at = text.find_first_of(" \n\t", at);
  }
  at = text.find_first_not_of(" \n\t", at);
  const size_t end = text.find_first_of(" \n\t<", at);
  const double original = std::stod(text.substr(at, end - at));
  ASSERT_EQ(original, e.point_data.at("von_mises").values[7]);
  char changed[64];
  std::snprintf(changed, sizeof changed, "%.17g", original * (1 + 1e-9));
  text.replace(at, end - at, changed);
  std::ofstream(file) << text;

  const std::vector<std::string> diff = differences(read_with_meshio({file}).at(file.string()), e);
  ASSERT_EQ(diff.size(), 1u);
  EXPECT_NE(diff[0].find("point_data 'von_mises': 1 of " + std::to_string(m.particle_count) + " values differ, the first at 7"),
            std::string::npos)
      << diff[0];
  std::printf("corrupted file: %s\n", diff[0].c_str());
  fs::remove_all(dir);
}

}  // namespace
}  // namespace palpate
