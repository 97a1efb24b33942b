// Tetrahedral mesh files (core/mesh_reader.h) and the "mesh" distribution built on
// them: gmsh 4.1 and 2.2, TetGen .node/.ele, nodal volumes, every refusal with its
// file, line and reason, and the scene rules (volumes, hex_fem, the box).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numeric>
#include <sstream>
#include <string>

#include <unistd.h>

#include "core/mesh_reader.h"
#include "core/model.h"
#include "core/scene.h"

namespace palpate {
namespace {

namespace fs = std::filesystem;

const fs::path kData = fs::path(PALPATE_SOURCE_DIR) / "tests" / "data";

// The unit cube as six positively oriented Kuhn tetrahedra around the diagonal from
// node 1 (0,0,0) to node 8 (1,1,1); node k is the corner with bits k-1 = (x, y, z).
// A point element (on node 1) and two triangles are ignored.
const std::string kGmsh41 = R"($MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
1
3 1 "the cube"
$EndPhysicalNames
$Entities
1 0 0 1
1 0 0 0 0
1 0 0 0 1 1 1 1 1 0
$EndEntities
$Nodes
1 8 1 8
3 1 0 8
1
2
3
4
5
6
7
8
0 0 0
1 0 0
0 1 0
1 1 0
0 0 1
1 0 1
0 1 1
1 1 1
$EndNodes
$Elements
3 9 1 9
0 1 15 1
1 1
2 1 2 2
2 1 2 4
3 1 4 3
3 1 4 6
4 1 2 4 8
5 1 6 2 8
6 1 4 3 8
7 1 3 7 8
8 1 5 6 8
9 1 7 5 8
$EndElements
)";

const std::string kGmsh22 = R"($MeshFormat
2.2 0 8
$EndMeshFormat
$PhysicalNames
2
2 7 "top face"
3 1 "the cube"
$EndPhysicalNames
$Nodes
8
1 0 0 0
2 1 0 0
3 0 1 0
4 1 1 0
5 0 0 1
6 1 0 1
7 0 1 1
8 1 1 1
$EndNodes
$Elements
9
1 15 2 0 1 1
2 2 2 0 1 1 2 4
3 4 2 1 1 1 2 4 8
4 4 2 1 1 1 6 2 8
5 4 2 1 1 1 4 3 8
6 4 2 1 1 1 3 7 8
7 4 2 1 1 1 5 6 8
8 4 2 1 1 1 7 5 8
9 2 2 0 1 1 4 3
$EndElements
)";

// A private folder for the files a test writes.
class MeshFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("palpate-mesh-" + std::to_string(getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path write(const std::string& name, const std::string& text) const {
    const fs::path p = dir_ / name;
    std::ofstream(p, std::ios::binary) << text;
    return p;
  }
  // The message of reading `text` as the file `name` (with an optional TetGen .ele), or "".
  std::string error_of(const std::string& name, const std::string& text, const std::string& ele = "",
                       int64_t max_nodes = kMaxMeshNodes) const {
    const fs::path p = write(name, text);
    if (!ele.empty()) write(fs::path(name).replace_extension(".ele").string(), ele);
    try {
      read_mesh(p, max_nodes);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "";
  }
  // The line (from 1) of `part` in `text`.
  static int line_of(const std::string& text, const std::string& part) {
    const size_t pos = text.find(part);
    EXPECT_NE(pos, std::string::npos) << part;
    return 1 + static_cast<int>(std::count(text.begin(), text.begin() + std::min(pos, text.size()), '\n'));
  }
  // "<dir>/<name>:<line of `part` in text>: "
  std::string at(const std::string& name, const std::string& text, const std::string& part) const {
    return (dir_ / name).string() + ":" + std::to_string(line_of(text, part)) + ": ";
  }
  static std::string replace(std::string text, const std::string& from, const std::string& to) {
    const size_t pos = text.find(from);
    EXPECT_NE(pos, std::string::npos) << from;
    EXPECT_EQ(text.find(from, pos + 1), std::string::npos) << "not unique: " << from;
    return text.replace(pos, from.size(), to);
  }

  fs::path dir_;
};

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

double signed_volume(const TetMesh& m, const std::array<int, 4>& t) {
  const Vec3 a = m.positions.col(t[0]);
  return (m.positions.col(t[1]) - a).dot((m.positions.col(t[2]) - a).cross(m.positions.col(t[3]) - a)) / 6.0;
}

// Volumes: the tetrahedra fill `box_volume`, each node holds a quarter of its tetrahedra,
// every tetrahedron is stored positive.
void expect_consistent(const TetMesh& m, double box_volume) {
  EXPECT_NEAR(m.total_volume, box_volume, 1e-12 * box_volume);
  EXPECT_NEAR(std::accumulate(m.nodal_volume.begin(), m.nodal_volume.end(), 0.0), box_volume, 1e-12 * box_volume);
  std::vector<double> lumped(m.positions.cols(), 0.0);
  for (const auto& t : m.tetrahedra) {
    const double V = signed_volume(m, t);
    EXPECT_GT(V, 0.0);
    for (int v : t) lumped[v] += V / 4;
  }
  for (size_t i = 0; i < lumped.size(); ++i) EXPECT_NEAR(m.nodal_volume[i], lumped[i], 1e-15);
  for (double v : m.nodal_volume) EXPECT_GT(v, 0.0);
}

TEST_F(MeshFiles, Gmsh41KeepsTheTetrahedra) {
  const TetMesh m = read_gmsh(write("cube.msh", kGmsh41));
  EXPECT_EQ(m.positions.cols(), 8);
  EXPECT_EQ(m.tetrahedra.size(), 6u);
  EXPECT_EQ(m.unused_nodes, 0);
  EXPECT_EQ(m.ignored_elements, 3);
  EXPECT_FALSE(m.reoriented);
  expect_consistent(m, 1.0);
  // Corner 1 (the diagonal's end) is in all six tetrahedra, corner 2 in two.
  EXPECT_NEAR(m.nodal_volume[0], 6 * (1.0 / 6) / 4, 1e-15);
  EXPECT_NEAR(m.nodal_volume[1], 2 * (1.0 / 6) / 4, 1e-15);
  EXPECT_EQ(m.positions.col(7), Vec3(1, 1, 1));
}

// Six positive tetrahedra of the unit cube with one corner moved (a fuzzer's find): no face
// is shared by more than two of them, one body, but two of them interpenetrate, so they
// hold more volume than their boundary encloses (the divergence theorem), and are refused.
TEST_F(MeshFiles, InterpenetratingTetrahedraAreRefused) {
  const std::string node = "8 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 1 1 0\n5 0 0 1\n6 1 0 1\n7 0 1 1\n8 1 1 1\n";
  const std::string ele = "6 4 0\n1 1 4 2 8\n2 1 2 6 8\n3 1 3 4 8\n4 2 6 3 8\n5 1 6 5 8\n6 1 5 7 8\n";
  const std::string e = error_of("o.node", node, ele);
  EXPECT_NE(e.find((dir_ / "o.ele").string() + ": the tetrahedra overlap: they hold"), std::string::npos) << e;
  EXPECT_NE(e.find("but their boundary encloses"), std::string::npos) << e;
}

TEST_F(MeshFiles, Gmsh22GivesTheSameMesh) {
  const TetMesh a = read_gmsh(write("a.msh", kGmsh41));
  const TetMesh b = read_gmsh(write("b.msh", kGmsh22));
  EXPECT_EQ(b.unused_nodes, 0);
  EXPECT_EQ(b.ignored_elements, 3);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.nodal_volume, b.nodal_volume);
  EXPECT_EQ(a.tetrahedra, b.tetrahedra);
}

TEST_F(MeshFiles, CrLfLineEndsAndTrailingBlanksAreFine) {
  std::string text;
  for (char c : kGmsh41) text += c == '\n' ? std::string(" \r\n") : std::string(1, c);
  expect_consistent(read_gmsh(write("crlf.msh", text)), 1.0);
}

TEST(MeshData, TheCommittedGmshMeshFillsTheUnitCube) {
  const TetMesh m = read_mesh(kData / "cube_tet_small.msh");
  EXPECT_GT(m.positions.cols(), 200);
  EXPECT_LT(m.positions.cols(), 600);
  EXPECT_EQ(m.unused_nodes, 0);
  expect_consistent(m, 1.0);
  EXPECT_EQ(declared_mesh_nodes(kData / "cube_tet_small.msh"), m.positions.cols());
}

TEST(MeshData, TheCommittedTetGenPairIsOneBasedAndNegativelyOriented) {
  const TetMesh m = read_mesh(kData / "cube_tetgen.node");
  EXPECT_EQ(m.positions.cols(), 9);
  EXPECT_EQ(m.tetrahedra.size(), 12u);
  EXPECT_TRUE(m.reoriented);
  expect_consistent(m, 1.0);
  EXPECT_EQ(m.positions.col(8), Vec3(0.5, 0.5, 0.5));
  EXPECT_NEAR(m.nodal_volume[8], 12 * (1.0 / 12) / 4, 1e-15);  // the centre is in every tetrahedron
  EXPECT_EQ(declared_mesh_nodes(kData / "cube_tetgen.node"), 9);
}

// The Kuhn cube as TetGen text, with 0- or 1-based indices.
std::string tetgen_node(int base) {
  std::ostringstream s;
  s << "8 3 0 0  # points, dimension, attributes, markers\n";
  for (int k = 0; k < 8; ++k) s << k + base << "  " << (k & 1) << ' ' << (k >> 1 & 1) << ' ' << (k >> 2 & 1) << '\n';
  return s.str();
}
std::string tetgen_ele(int base, bool ten_nodes = false, bool swap = false) {
  const int tets[6][4] = {{1, 2, 4, 8}, {1, 6, 2, 8}, {1, 4, 3, 8}, {1, 3, 7, 8}, {1, 5, 6, 8}, {1, 7, 5, 8}};
  std::ostringstream s;
  s << "6 " << (ten_nodes ? 10 : 4) << " 0\n";
  for (int t = 0; t < 6; ++t) {
    s << t + base;
    for (int a = 0; a < 4; ++a) s << ' ' << tets[t][swap && (a == 1 || a == 2) ? 3 - a : a] - 1 + base;
    if (ten_nodes)
      for (int a = 0; a < 6; ++a) s << ' ' << tets[t][a % 4] - 1 + base;
    s << '\n';
  }
  return s.str();
}

TEST_F(MeshFiles, TetGenZeroAndOneBasedAndTenNodeElements) {
  write("zero.ele", tetgen_ele(0));
  write("one.ele", tetgen_ele(1));
  write("ten.ele", tetgen_ele(1, true));
  const TetMesh zero = read_tetgen(write("zero.node", tetgen_node(0)));
  const TetMesh one = read_tetgen(write("one.node", tetgen_node(1)));
  const TetMesh ten = read_tetgen(write("ten.node", tetgen_node(1)));
  expect_consistent(zero, 1.0);
  EXPECT_EQ(zero.positions, one.positions);
  EXPECT_EQ(zero.tetrahedra, one.tetrahedra);
  EXPECT_EQ(ten.tetrahedra, one.tetrahedra);
  const TetMesh gmsh = read_gmsh(write("cube.msh", kGmsh41));
  EXPECT_EQ(one.tetrahedra, gmsh.tetrahedra);
}

TEST_F(MeshFiles, ScaledToTheDefaultCubeTheVolumesSumToItsVolume) {
  std::string text = "8 3 0 0\n";
  for (int k = 0; k < 8; ++k)
    text += std::to_string(k) + "  " + (k & 1 ? "1" : "-1") + " " + (k >> 1 & 1 ? "1" : "-1") + " " +
            (k >> 2 & 1 ? "0" : "-2") + "\n";
  write("big.ele", tetgen_ele(0));
  expect_consistent(read_tetgen(write("big.node", text)), 8.0);
}

// ---------------------------------------------------------------------------
// Refusals: file, line and reason.

TEST_F(MeshFiles, MalformedNumber) {
  const std::string text = replace(kGmsh41, "0 1 1\n", "0 1 1x\n");
  EXPECT_EQ(error_of("m.msh", text), at("m.msh", text, "1x") + "z: expected a number, got '1x'");
}

TEST_F(MeshFiles, NotANumberCoordinate) {
  const std::string text = replace(kGmsh22, "7 0 1 1", "7 0 nan 1");
  EXPECT_EQ(error_of("m.msh", text), at("m.msh", text, "nan") + "y: must be a finite number, got 'nan'");
  const std::string huge = replace(kGmsh22, "7 0 1 1", "7 0 1e300 1");
  EXPECT_TRUE(contains(error_of("m.msh", huge), "exceeds 1e12")) << error_of("m.msh", huge);
  const std::string overflow = replace(kGmsh22, "7 0 1 1", "7 0 1e999 1");
  EXPECT_TRUE(contains(error_of("m.msh", overflow), "'1e999' is out of range"));
}

TEST_F(MeshFiles, MissingSections) {
  const std::string no_elements = kGmsh41.substr(0, kGmsh41.find("$Elements"));
  EXPECT_EQ(error_of("m.msh", no_elements), (dir_ / "m.msh").string() + ": no $Elements section");
  const std::string no_nodes = kGmsh22.substr(0, kGmsh22.find("$Nodes")) + kGmsh22.substr(kGmsh22.find("$Elements"));
  EXPECT_EQ(error_of("m.msh", no_nodes), (dir_ / "m.msh").string() + ": no $Nodes section");
  const std::string only_format = kGmsh22.substr(0, kGmsh22.find("$Nodes"));
  EXPECT_EQ(error_of("m.msh", only_format), (dir_ / "m.msh").string() + ": no $Nodes section");
  EXPECT_EQ(error_of("m.msh", ""), (dir_ / "m.msh").string() + ": empty file, expected a gmsh mesh");
  EXPECT_EQ(error_of("m.msh", "hello\n"),
            (dir_ / "m.msh").string() + ":1: the file must start with $MeshFormat (is it a gmsh .msh file?), got 'hello'");
  const std::string unclosed = replace(kGmsh41, "$EndEntities\n", "");
  EXPECT_EQ(error_of("m.msh", unclosed),
            at("m.msh", unclosed, "$Nodes") + "expected $EndEntities, got '$Nodes'");  // $Entities is read (4.1)
  const std::string names = replace(kGmsh41, "$EndPhysicalNames\n", "");
  EXPECT_EQ(error_of("m.msh", names), at("m.msh", names, "$Entities") + "expected $EndPhysicalNames, got '$Entities'");
  const std::string truncated = kGmsh41.substr(0, kGmsh41.find("9 1 7 5 8"));
  EXPECT_TRUE(contains(error_of("m.msh", truncated), "unexpected end of file, expected elementTag"));
}

TEST_F(MeshFiles, FormatsThatAreNotRead) {
  const std::string binary = replace(kGmsh41, "4.1 0 8", "4.1 1 8");
  EXPECT_EQ(error_of("m.msh", binary),
            at("m.msh", binary, "4.1") + "binary .msh files are not supported: save the mesh as ASCII (gmsh option Mesh.Binary = 0)");
  EXPECT_TRUE(contains(error_of("m.msh", replace(kGmsh41, "4.1 0 8", "4 0 8")), "gmsh format 4.0 is not supported"));
  EXPECT_TRUE(contains(error_of("m.msh", replace(kGmsh41, "4.1 0 8", "3.0 0 8")), "unknown gmsh format version '3.0'"));
  EXPECT_EQ(error_of("m.vtk", kGmsh41),
            (dir_ / "m.vtk").string() +
                ": unknown mesh format '.vtk' (known: .msh, gmsh 4.1 or 2.2 ASCII; .node with its .ele, TetGen)");
  const std::string triangles_only = kGmsh22.substr(0, kGmsh22.find("$Elements")) +
                                     "$Elements\n1\n1 2 2 0 1 1 2 4\n$EndElements\n";
  EXPECT_EQ(error_of("m.msh", triangles_only),
            (dir_ / "m.msh").string() +
                ": no 4-node tetrahedra (element type 4) in $Elements, 1 other elements (a volume mesh of order 1 "
                "is needed: gmsh -3 -order 1)");
}

TEST_F(MeshFiles, CountsThatDoNotMatch) {
  const std::string nodes = replace(kGmsh41, "1 8 1 8", "1 9 1 8");
  EXPECT_TRUE(contains(error_of("m.msh", nodes), "the node blocks hold 8 nodes, the $Nodes header says 9"))
      << error_of("m.msh", nodes);
  const std::string elements = replace(kGmsh41, "3 9 1 9", "3 8 1 9");
  EXPECT_TRUE(contains(error_of("m.msh", elements), "the element blocks hold more than the 8 elements the $Elements header declares"))
      << error_of("m.msh", elements);
  const std::string v2 = replace(kGmsh22, "$Nodes\n8\n", "$Nodes\n9\n");
  EXPECT_TRUE(contains(error_of("m.msh", v2), "node-number: expected an integer, got '$EndNodes'"));
}

TEST_F(MeshFiles, IndicesOutOfRangeAndDuplicateTags) {
  const std::string unknown = replace(kGmsh41, "9 1 7 5 8", "9 1 7 5 9");
  EXPECT_EQ(error_of("m.msh", unknown), at("m.msh", unknown, "9 1 7 5 9") + "tetrahedron 9: node tag 9 is not in $Nodes");
  const std::string duplicate = replace(kGmsh22, "8 1 1 1", "2 1 1 1");
  EXPECT_EQ(error_of("m.msh", duplicate),
            at("m.msh", duplicate, "2 1 1 1") + "node tag 2 appears twice (first at line " +
                std::to_string(line_of(duplicate, "2 1 0 0")) + ")");
  const std::string ele = replace(tetgen_ele(1), "6 1 7 5 8", "6 1 7 5 9");
  EXPECT_EQ(error_of("c.node", tetgen_node(1), ele),
            at("c.ele", ele, "6 1 7 5 9") + "tetrahedron 6: node index 9 is out of range [1, 8]");
  const std::string zero = replace(tetgen_ele(0), "5 0 6 4 7", "5 0 6 4 8");
  EXPECT_TRUE(contains(error_of("c.node", tetgen_node(0), zero), "node index 8 is out of range [0, 7]"));
}

TEST_F(MeshFiles, DegenerateTetrahedra) {
  // A repeated node, and a flat tetrahedron (node 8 moved into the plane of 1, 2, 4 would
  // coincide with 4: move it to z = 0 beside the cube instead).
  const std::string repeated = replace(kGmsh22, "3 4 2 1 1 1 2 4 8", "3 4 2 1 1 1 2 4 4");
  EXPECT_EQ(error_of("m.msh", repeated),
            at("m.msh", repeated, "1 2 4 4") + "tetrahedron 3 uses node 4 (line " +
                std::to_string(line_of(repeated, "4 1 1 0")) + ") twice (degenerate)");
  const std::string node = "5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 2 2 0\n";
  const std::string ele = "2 4 0\n1 1 2 3 4\n2 1 2 3 5\n";
  EXPECT_EQ(error_of("flat.node", node, ele),
            (dir_ / "flat.ele").string() + ":3: tetrahedron 2 is degenerate: volume 0 m^3 with longest edge 2.8284271247461903 m "
                                           "(|V| must exceed 1e-12 L^3): its four nodes are (nearly) in one plane");
}

// The tolerance is relative: 1e-12 L^3 refuses a flat element at any scale and keeps a
// good one however small. One tetrahedron (0,0,0), (1,0,0), (0,1,0), (0.3, 0.3, h),
// scaled by s: V = s^3 h / 6, L = s sqrt(2), so it is refused for h <= 6e-12 * 2^1.5 = 1.7e-11.
TEST_F(MeshFiles, TheDegenerateToleranceIsRelativeToTheEdgeLength) {
  const auto one = [&](double s, double h) {
    std::ostringstream node;
    node.precision(17);
    node << "4 3 0 0\n1 0 0 0\n2 " << s << " 0 0\n3 0 " << s << " 0\n4 " << 0.3 * s << ' ' << 0.3 * s << ' ' << s * h << '\n';
    return error_of("t.node", node.str(), "1 4 0\n1 1 2 3 4\n");
  };
  for (double s : {1e-6, 1.0, 1e3}) {
    EXPECT_EQ(one(s, 1e-9), "") << s;
    EXPECT_EQ(one(s, 2e-11), "") << s;
    EXPECT_TRUE(contains(one(s, 1.5e-11), "t.ele:2: tetrahedron 1 is degenerate")) << s << ": " << one(s, 1.5e-11);
  }
  // A cube of 1 um edge (a far smaller mesh than any absolute tolerance would allow).
  std::string node = "8 3 0 0\n";
  for (int k = 0; k < 8; ++k)
    node += std::to_string(k + 1) + " " + (k & 1 ? "1e-6" : "0") + " " + (k >> 1 & 1 ? "1e-6" : "0") + " " +
            (k >> 2 & 1 ? "1e-6" : "0") + "\n";
  write("micro.ele", tetgen_ele(1));
  expect_consistent(read_tetgen(write("micro.node", node)), 1e-18);
}

TEST_F(MeshFiles, InvertedTetrahedron) {
  const std::string text = replace(kGmsh41, "9 1 7 5 8", "9 1 5 7 8");
  EXPECT_EQ(error_of("m.msh", text),
            at("m.msh", text, "9 1 5 7 8") +
                "tetrahedron 9 is inverted: signed volume -0.16666666666666666 m^3 (nodes 1 5 7 8: seen from the fourth, the first "
                "three turn clockwise) while 5 of the file's 6 tetrahedra are positive: the mesh is tangled or this "
                "element's nodes are misnumbered (regenerate the mesh, or swap two of its nodes)");
  // The first tetrahedron inverted: the file's orientation is its majority's, so the
  // message names that element, not the five others.
  const std::string first = replace(kGmsh22, "3 4 2 1 1 1 2 4 8", "3 4 2 1 1 2 1 4 8");
  EXPECT_TRUE(contains(error_of("m.msh", first), at("m.msh", first, "2 1 4 8") + "tetrahedron 3 is inverted"))
      << error_of("m.msh", first);
}

// A mirrored file (all tetrahedra negative) is accepted; one positive element in it is
// the inverted one.
TEST_F(MeshFiles, InvertedInANegativelyOrientedFile) {
  const std::string mirrored = tetgen_ele(1, false, /*swap=*/true);
  write("mirror.ele", mirrored);
  const TetMesh mirror = read_tetgen(write("mirror.node", tetgen_node(1)));
  EXPECT_TRUE(mirror.reoriented);
  expect_consistent(mirror, 1.0);
  const std::string one_positive = replace(mirrored, "2 1 2 6 8", "2 1 6 2 8");
  EXPECT_EQ(error_of("c.node", tetgen_node(1), one_positive),
            at("c.ele", one_positive, "2 1 6 2 8") +
                "tetrahedron 2 is inverted: signed volume 0.16666666666666666 m^3 (nodes 1 6 2 8: seen from the fourth, the first "
                "three turn counterclockwise) while 5 of the file's 6 tetrahedra are negative: the mesh is tangled or "
                "this element's nodes are misnumbered (regenerate the mesh, or swap two of its nodes)");
}

// A node no tetrahedron references is refused, named by its number and line: a gmsh
// geometry point (4.1 and 2.2), a TetGen point.
TEST_F(MeshFiles, UnusedNodes) {
  const std::string v41 = replace(replace(kGmsh41, "1 8 1 8\n", "2 9 1 20\n0 1 0 1\n20\n5 5 5\n"), "1 1\n2 1 2 2", "1 20\n2 1 2 2");
  const std::string reason =
      " is used by no tetrahedron (a geometry point, or a node of lower-dimensional elements only): every node "
      "must be a vertex of the body's tetrahedra; remove it, or regenerate the mesh without free points";
  EXPECT_EQ(error_of("m.msh", v41), at("m.msh", v41, "5 5 5") + "node 20" + reason);
  const std::string v22 = replace(replace(kGmsh22, "$Nodes\n8\n", "$Nodes\n9\n"), "8 1 1 1\n", "8 1 1 1\n20 5 5 5\n");
  EXPECT_EQ(error_of("m.msh", v22), at("m.msh", v22, "20 5 5 5") + "node 20" + reason);
  // A node of the triangles only (node 4 dropped from the tetrahedra by remeshing them
  // around a new centre would do; here: a triangle on a node of its own).
  const std::string tri = replace(replace(kGmsh22, "$Nodes\n8\n", "$Nodes\n9\n"), "8 1 1 1\n", "8 1 1 1\n9 2 2 2\n");
  EXPECT_EQ(error_of("m.msh", replace(tri, "9 2 2 0 1 1 4 3", "9 2 2 0 1 1 4 9")),
            at("m.msh", tri, "9 2 2 2") + "node 9" + reason);
  const std::string node = replace(tetgen_node(0), "8 3 0 0", "9 3 0 0") + "8  3 3 3\n";
  EXPECT_EQ(error_of("c.node", node, tetgen_ele(0)), (dir_ / "c.node").string() + ":10: node 8" + reason);
}

// A 10-node TetGen element: its six mid-edge nodes are referenced, dropped and counted.
TEST_F(MeshFiles, TenNodeMidEdgeNodesAreDropped) {
  const std::string node =
      "10 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 0.5 0 0\n6 0.5 0.5 0\n7 0 0.5 0\n8 0 0 0.5\n9 0.5 0 0.5\n10 0 0.5 0.5\n";
  write("q.ele", "1 10 0\n1 1 2 3 4 5 6 7 8 9 10\n");
  const TetMesh m = read_tetgen(write("q.node", node));
  EXPECT_EQ(m.positions.cols(), 4);
  EXPECT_EQ(m.unused_nodes, 6);
  expect_consistent(m, 1.0 / 6);
  // ... but a node referenced by nothing is refused there too.
  EXPECT_TRUE(contains(error_of("r.node", replace(node, "10 3 0 0", "11 3 0 0") + "11 1 1 1\n", "1 10 0\n1 1 2 3 4 5 6 7 8 9 10\n"),
                       "r.node:12: node 11 is used by no tetrahedron"));
}

// Two unit cubes side by side as TetGen text: `gap` m apart along x (0: sharing a face).
std::string two_cubes_node(double gap) {
  std::ostringstream s;
  s << "16 3 0 0\n";
  for (int c = 0; c < 2; ++c)
    for (int k = 0; k < 8; ++k)
      s << 8 * c + k + 1 << "  " << (k & 1) + c * (1 + gap) << ' ' << (k >> 1 & 1) << ' ' << (k >> 2 & 1) << '\n';
  return s.str();
}

TEST_F(MeshFiles, DisconnectedParts) {
  // Two separate cubes: 12 tetrahedra in two parts of six.
  const int tets[6][4] = {{1, 2, 4, 8}, {1, 6, 2, 8}, {1, 4, 3, 8}, {1, 3, 7, 8}, {1, 5, 6, 8}, {1, 7, 5, 8}};
  std::ostringstream apart_ele;
  apart_ele << "12 4 0\n";
  for (int c = 0; c < 2; ++c)
    for (int t = 0; t < 6; ++t) {
      apart_ele << 6 * c + t + 1;
      for (int a = 0; a < 4; ++a) apart_ele << ' ' << tets[t][a] + 8 * c;
      apart_ele << '\n';
    }
  const std::string ele = apart_ele.str();
  const std::string apart = error_of("c.node", two_cubes_node(0.5), ele);
  EXPECT_EQ(apart, (dir_ / "c.ele").string() +
                       ":8: the tetrahedra form 2 parts joined by no shared face, and no part shares a node with another: "
                       "a body must be one part. Tetrahedron 7 (this line) is in a part of 6 tetrahedra, the largest part "
                       "has 6 (tetrahedron 1, line 2); mesh one volume, or remove the other parts");
  // A single tetrahedron beside the cube, touching it at the corner (1, 1, 1) only (a pinch).
  const std::string pinch_node = tetgen_node(1).replace(0, 1, "11") + "9  2 1 1\n10 1 2 1\n11 1 1 2\n";
  const std::string pinch_ele = replace(tetgen_ele(1), "6 4 0", "7 4 0") + "7 8 9 10 11\n";
  const std::string pinch = error_of("p.node", pinch_node, pinch_ele);
  EXPECT_EQ(pinch, (dir_ / "p.ele").string() +
                       ":8: the tetrahedra form 2 parts joined by no shared face; they touch only at edges or nodes (a "
                       "pinch: no material joins them): a body must be one part. Tetrahedron 7 (this line) is in a part "
                       "of 1 tetrahedron, the largest part has 6 (tetrahedron 1, line 2); mesh one volume, or remove the "
                       "other parts");
  // The control: the second cube against the first, sharing its face x = 1 (the mirror
  // image of the first in x = 1, so the face's diagonals match; the mirrored tetrahedra
  // list their second and third nodes swapped to stay positive) is one body of 2 m^3.
  std::ostringstream shared_node, shared_ele;
  shared_node << "12 3 0 0\n";
  for (int k = 0; k < 8; ++k) shared_node << k + 1 << ' ' << (k & 1) << ' ' << (k >> 1 & 1) << ' ' << (k >> 2 & 1) << '\n';
  for (int k = 0; k < 4; ++k) shared_node << 9 + k << " 2 " << (k & 1) << ' ' << (k >> 1 & 1) << '\n';
  shared_ele << "12 4 0\n";
  for (int t = 0; t < 6; ++t) {
    shared_ele << t + 1;
    for (int a = 0; a < 4; ++a) shared_ele << ' ' << tets[t][a];
    shared_ele << '\n' << t + 7;
    for (int a : {0, 2, 1, 3}) {
      const int k = tets[t][a] - 1;  // mirrored in x = 1: the x = 0 corners go to x = 2
      shared_ele << ' ' << (k & 1 ? k + 1 : 9 + (k >> 1));
    }
    shared_ele << '\n';
  }
  write("two.ele", shared_ele.str());
  const TetMesh two = read_tetgen(write("two.node", shared_node.str()));
  EXPECT_EQ(two.positions.cols(), 12);
  EXPECT_FALSE(two.reoriented);
  expect_consistent(two, 2.0);
}

// Duplicated or overlapping tetrahedra: a face bounds at most two.
TEST_F(MeshFiles, OverlappingTetrahedra) {
  // Node 9 below the cube's interior face (1, 2, 8), which tetrahedra 3 and 4 share.
  const std::string text =
      replace(replace(replace(kGmsh22, "$Elements\n9\n", "$Elements\n10\n"), "$EndElements", "10 4 2 1 1 1 2 8 9\n$EndElements"),
              "$Nodes\n8\n", "$Nodes\n9\n") ;
  const std::string with_node = replace(text, "8 1 1 1\n", "8 1 1 1\n9 0.5 -1 0.5\n");
  EXPECT_EQ(error_of("m.msh", with_node),
            at("m.msh", with_node, "10 4 2 1 1 1 2 8 9") +
                "tetrahedron 10 shares a face with tetrahedra 3 (line " + std::to_string(line_of(with_node, "3 4 2 1 1 1 2 4 8")) +
                ") and 4 (line " + std::to_string(line_of(with_node, "4 4 2 1 1 1 6 2 8")) +
                "): a face bounds at most two tetrahedra (duplicated or overlapping elements)");
  // A repeated tetrahedron (here the mesh's only other one: no face has three).
  const std::string node = "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n";
  EXPECT_EQ(error_of("d.node", node, "2 4 0\n1 1 2 3 4\n2 2 3 1 4\n"),
            (dir_ / "d.ele").string() + ":3: tetrahedron 2 repeats tetrahedron 1 (line 2): the same four nodes");
}

TEST_F(MeshFiles, CoincidentNodes) {
  // Two tetrahedra touching at a point through two distinct nodes (a crack).
  const std::string node = "8 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 0 0\n6 2 0 0\n7 1 1 0\n8 1 0 1\n";
  EXPECT_EQ(error_of("crack.node", node, "2 4 0\n1 1 2 3 4\n2 5 6 7 8\n"),
            (dir_ / "crack.node").string() + ":6: this node coincides with the node at line 3 (1, 0, 0)");
}

TEST_F(MeshFiles, TooManyNodes) {
  EXPECT_EQ(error_of("m.msh", kGmsh41, "", 7), at("m.msh", kGmsh41, "1 8 1 8") + "8 nodes exceed the limit of 7");
  EXPECT_EQ(error_of("c.node", tetgen_node(1), tetgen_ele(1), 7), (dir_ / "c.node").string() + ":1: 8 nodes exceed the limit of 7");
}

TEST_F(MeshFiles, TetGenStructure) {
  EXPECT_EQ(error_of("c.node", replace(tetgen_node(1), "\n1  0 0 0", "\n2  0 0 0"), tetgen_ele(1)),
            (dir_ / "c.node").string() + ":2: the first point index must be 0 or 1, got 2");
  EXPECT_EQ(error_of("c.node", replace(tetgen_node(1), "\n5  0 0 1", "\n6  0 0 1"), tetgen_ele(1)),
            (dir_ / "c.node").string() + ":6: point index 6 where 5 was expected (indices must be consecutive)");
  EXPECT_EQ(error_of("c.node", replace(tetgen_node(1), "\n5  0 0 1", "\n5  0 0 1 3"), tetgen_ele(1)),
            (dir_ / "c.node").string() + ":6: unexpected '3' after a point (index, x, y, z, 0 attributes, 0 markers)");
  EXPECT_EQ(error_of("c.node", replace(tetgen_node(1), "8 3 0 0", "8 2 0 0"), tetgen_ele(1)),
            (dir_ / "c.node").string() + ":1: dimension: must be in [3, 3], got 2");
  EXPECT_EQ(error_of("c.node", tetgen_node(1), replace(tetgen_ele(1), "6 4 0", "6 5 0")),
            (dir_ / "c.ele").string() + ":1: nodes per tetrahedron: must be 4 or 10, got 5");
  EXPECT_EQ(error_of("c.node", tetgen_node(1) + "9 1 1 1\n", tetgen_ele(1)),
            (dir_ / "c.node").string() + ":10: unexpected '9' after the 8 points");
  // The .ele is missing.
  const fs::path lonely = write("lonely.node", tetgen_node(1));
  try {
    read_mesh(lonely);
    ADD_FAILURE() << "accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), (dir_ / "lonely.ele").string() + ": cannot open TetGen .ele file (the .node file's sibling)");
  }
}

// $PhysicalNames: read in 4.1 and 2.2 (names with spaces), looked up by dimension and name.
TEST_F(MeshFiles, PhysicalNames) {
  const fs::path v41 = write("a.msh", kGmsh41);
  const TetMesh a = read_gmsh(v41);
  ASSERT_EQ(a.physical_names.size(), 1u);
  EXPECT_EQ(a.physical_names[0].dimension, 3);
  EXPECT_EQ(a.physical_names[0].tag, 1);
  EXPECT_EQ(a.physical_names[0].name, "the cube");
  EXPECT_EQ(a.physical_names[0].line, line_of(kGmsh41, "3 1 \"the cube\""));
  const fs::path v22 = write("b.msh", kGmsh22);
  const TetMesh b = read_gmsh(v22);
  ASSERT_EQ(b.physical_names.size(), 2u);
  EXPECT_EQ(physical_group_tag(b, v22, 2, "top face"), 7);
  EXPECT_EQ(physical_group_tag(b, v22, 3, "the cube"), 1);
  write("c.ele", tetgen_ele(1));
  EXPECT_TRUE(read_tetgen(write("c.node", tetgen_node(1))).physical_names.empty());
  // Unknown names (or a known name at another dimension).
  try {
    physical_group_tag(b, v22, 2, "the cube");
    ADD_FAILURE() << "found";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), v22.string() + ": no physical group of dimension 2 is named 'the cube' (the file names 'top face')");
  }
  try {
    physical_group_tag(b, v22, 1, "edge");
    ADD_FAILURE() << "found";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), v22.string() + ": no physical group of dimension 1 is named 'edge' (the file names none of that dimension)");
  }
}

TEST_F(MeshFiles, PhysicalNamesThatAreRefused) {
  const auto names = [](const std::string& entries) {
    return replace(kGmsh22, "2\n2 7 \"top face\"\n3 1 \"the cube\"\n", entries);
  };
  const auto check = [&](const std::string& entries, const std::string& part, const std::string& reason) {
    const std::string text = names(entries);
    EXPECT_EQ(error_of("m.msh", text), at("m.msh", text, part) + reason) << entries;
  };
  check("2\n2 7 \"top\"\n2 7 \"bottom\"\n", "2 7 \"bottom\"",
        "physical group 7 of dimension 2 is named twice ('top' at line 6, 'bottom' here)");
  check("2\n2 7 \"top\"\n2 8 \"top\"\n", "2 8 \"top\"",
        "physical name 'top' is given to two groups of dimension 2 (tag 7 at line 6, tag 8 here): a name must identify one group");
  check("1\n2 7 top\n", "2 7 top", "physical name: expected a name in double quotes, got 'top'");
  check("1\n2 7 \"top\n", "2 7 \"top", "physical name: the closing double quote is missing on this line");
  check("1\n2 7 \"\"\n", "2 7 \"\"", "physical name: empty (\"\"): a group must be named to be referred to");
  check("1\n4 7 \"top\"\n", "4 7", "physical name dimension: must be in [0, 3], got 4");
  check("1\n2 0 \"top\"\n", "2 0 \"", "physicalTag: must be in [1, " + std::to_string(std::numeric_limits<int64_t>::max() / 2) + "], got 0");
  check("1\n2 7 \"top\" 5\n", "2 7 \"top\" 5", "unexpected '5' after a physical name");
  check("1\n2 7\n\"top\"\n", "\"top\"", "physical name: expected on the line of its dimension and tag");
  check("3\n2 7 \"top\"\n", "$EndPhysicalNames", "physical name dimension: expected an integer, got '$EndPhysicalNames'");
  const std::string twice = kGmsh41 + "$PhysicalNames\n0\n$EndPhysicalNames\n";
  EXPECT_EQ(error_of("m.msh", twice), (dir_ / "m.msh").string() + ":" + std::to_string(line_of(twice, "$EndElements") + 1) +
                                          ": a second $PhysicalNames section");
}

// Every shipped mesh passes the checks (and the committed test meshes).
TEST(MeshData, TheShippedMeshesPassTheChecks) {
  int count = 0;
  for (const fs::path& dir : {fs::path(PALPATE_SOURCE_DIR) / "scenes" / "meshes", kData})
    for (const auto& entry : fs::directory_iterator(dir)) {
      if (!known_mesh_extension(entry.path())) continue;
      SCOPED_TRACE(entry.path().string());
      const TetMesh m = read_mesh(entry.path());
      EXPECT_EQ(m.unused_nodes, 0);
      EXPECT_GT(m.total_volume, 0.0);
      EXPECT_EQ(declared_mesh_nodes(entry.path()), m.positions.cols());
      ++count;
    }
  EXPECT_GE(count, 6);  // 3 scenes/meshes, 2 gmsh and 1 TetGen in tests/data
}

TEST_F(MeshFiles, DeclaredNodeCountIsReadFromTheHeader) {
  EXPECT_EQ(declared_mesh_nodes(write("a.msh", kGmsh41)), 8);
  EXPECT_EQ(declared_mesh_nodes(write("b.msh", kGmsh22)), 8);
  EXPECT_EQ(declared_mesh_nodes(write("c.node", "# comment\n123456789 3 0 0\n")), 123456789);
  EXPECT_THROW(declared_mesh_nodes(write("d.msh", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n")), std::runtime_error);
}

// ---------------------------------------------------------------------------
// The "mesh" distribution in scenes and models.

std::string mesh_scene(const std::string& file, const std::string& extra = R"(, "mls": {"volumes": "mesh"})",
                       const std::string& box = R"("box": {"min": [0, 0, 0], "max": [1, 1, 1]}, )") {
  return R"({"body": {)" + box + R"("distribution": {"type": "mesh", "file": ")" + file + R"("}})" + extra + "}";
}

SceneError scene_error(const std::string& json, const fs::path& base = kData) {
  try {
    parse_scene(json, "inline", base);
  } catch (const SceneError& e) {
    return e;
  }
  ADD_FAILURE() << "accepted: " << json;
  return SceneError("", "", "");
}

TEST(MeshScene, FileIsResolvedAgainstTheSceneFolder) {
  const Scene s = parse_scene(mesh_scene("cube_tet_small.msh"), "inline", kData);
  EXPECT_EQ(s.distribution.type, DistributionType::mesh);
  EXPECT_EQ(s.mls.volumes, VolumeRule::mesh);
  EXPECT_TRUE(s.distribution.mesh_file.is_absolute());
  EXPECT_TRUE(fs::equivalent(s.distribution.mesh_file, kData / "cube_tet_small.msh"));
  EXPECT_STREQ(to_string(DistributionType::mesh), "mesh");
}

TEST(MeshScene, Refusals) {
  SceneError e = scene_error(mesh_scene("cube_tet_small.msh", ""));
  EXPECT_EQ(e.field(), "/mls/volumes");
  EXPECT_EQ(e.reason(), "a 'mesh' distribution takes its volumes from the tetrahedra: set \"volumes\": \"mesh\" (got "
                        "'kernel', the default)");
  e = scene_error(mesh_scene("cube_tet_small.msh", R"(, "mls": {"volumes": "lattice"})"));
  EXPECT_TRUE(contains(e.reason(), "(got 'lattice')")) << e.reason();
  e = scene_error(R"({"mls": {"volumes": "mesh"}})");
  EXPECT_EQ(e.field(), "/mls/volumes");
  EXPECT_TRUE(contains(e.reason(), "'mesh' volumes need a 'mesh' distribution")) << e.reason();
  e = scene_error(R"({"body": {"distribution": {"type": "mesh"}}, "mls": {"volumes": "mesh"}})");
  EXPECT_EQ(e.field(), "/body/distribution/file");
  EXPECT_TRUE(contains(e.reason(), "required when type is 'mesh'")) << e.reason();
  e = scene_error(mesh_scene("missing.msh"));
  EXPECT_EQ(e.field(), "/body/distribution/file");
  EXPECT_TRUE(contains(e.reason(), "mesh file 'missing.msh' not found")) << e.reason();
  e = scene_error(mesh_scene("cube_tetgen.ele"));
  EXPECT_TRUE(contains(e.reason(), "unknown mesh format '.ele'")) << e.reason();
  e = scene_error(mesh_scene("cube_tet_small.msh", R"(, "model": "hex_fem")"));
  EXPECT_EQ(e.field(), "/body/distribution/type");
  EXPECT_TRUE(contains(e.reason(), "the hex_fem model meshes a lattice with bricks and cannot use a tetrahedral 'mesh' cloud"))
      << e.reason();
}

TEST(MeshScene, TetGenNeedsItsElementFile) {
  const fs::path dir = fs::temp_directory_path() / ("palpate-mesh-scene-" + std::to_string(getpid()));
  fs::create_directories(dir);
  fs::copy_file(kData / "cube_tetgen.node", dir / "alone.node", fs::copy_options::overwrite_existing);
  const SceneError e = scene_error(mesh_scene("alone.node"), dir);
  fs::remove_all(dir);
  EXPECT_EQ(e.field(), "/body/distribution/file");
  EXPECT_TRUE(contains(e.reason(), "the TetGen element file of 'alone.node' not found")) << e.reason();
}

TEST(MeshScene, ModelOfTheSmallMeshReportsItsCloud) {
  const Model m = build_model(parse_scene(mesh_scene("cube_tet_small.msh", R"(, "mls": {"volumes": "mesh", "neighbors": 20,
      "support_rule": "kth_distance", "support_factor": 1.1}, "fixed": ["bottom", "sides"])"),
                                          "inline", kData));
  const TetMesh mesh = read_mesh(kData / "cube_tet_small.msh");
  EXPECT_EQ(m.particle_count, mesh.positions.cols());
  EXPECT_EQ(m.mesh_tetrahedra, static_cast<int64_t>(mesh.tetrahedra.size()));
  EXPECT_EQ(m.mesh_unused_nodes, 0);
  EXPECT_NEAR(m.total_volume, m.box_volume, 1e-12);
  EXPECT_EQ(m.box_volume, 1.0);
  for (int i = 0; i < m.particle_count; ++i) {
    EXPECT_EQ(m.volume[i], mesh.nodal_volume[i]);
    EXPECT_NEAR(m.mass[i], 1000 * mesh.nodal_volume[i], 1e-12);
    const Vec3 X = m.rest_position.col(i);
    const bool on_fixed = X.z() == 0 || X.x() == 0 || X.x() == 1 || X.y() == 0 || X.y() == 1;
    EXPECT_EQ(m.fixed[i] != 0, on_fixed) << i;
  }
  EXPECT_GT(m.min_spacing, 0.0);
  EXPECT_GT(m.max_spacing, m.min_spacing);
  EXPECT_TRUE(std::isfinite(m.worst_condition));
  EXPECT_GT(m.worst_condition, 1.0);
  EXPECT_GT(m.integration_residual_nodal, 0.0);
}

TEST(MeshScene, TheMeshMustFillTheBox) {
  // The unit-cube mesh against the 2 m cube (given: without a box any shape is accepted).
  try {
    build_model(parse_scene(mesh_scene("cube_tet_small.msh", R"(, "mls": {"volumes": "mesh"})",
                                       R"("box": {"min": [-1, -1, -2], "max": [1, 1, 0]}, )"),
                            "inline", kData));
    ADD_FAILURE() << "accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/body/distribution/file");
    EXPECT_TRUE(contains(e.reason(), "not /body/box [-1, -1, -2] ... [1, 1, 0]: the mesh must fill the box")) << e.reason();
  }
  // A hole: the committed TetGen cube without its last tetrahedron.
  const fs::path dir = fs::temp_directory_path() / ("palpate-mesh-hole-" + std::to_string(getpid()));
  fs::create_directories(dir);
  fs::copy_file(kData / "cube_tetgen.node", dir / "hole.node", fs::copy_options::overwrite_existing);
  {
    std::ifstream in(kData / "cube_tetgen.ele");
    std::ofstream out(dir / "hole.ele");
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("12  4  1", 0) == 0) line = "11  4  1";
      if (line.rfind("  12 ", 0) == 0) continue;
      out << line << '\n';
    }
  }
  try {
    build_model(parse_scene(mesh_scene("hole.node", R"(, "mls": {"volumes": "mesh", "neighbors": 4}, "fixed": [])"),
                            "inline", dir));
    ADD_FAILURE() << "accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/body/distribution/file");
    EXPECT_TRUE(contains(e.reason(), "hold 0.916666667 m^3, the box 1 m^3 (a hole, an overlap or another shape)"))
        << e.reason();
  }
  fs::remove_all(dir);
  // The whole TetGen cube builds: 9 particles, exact volumes.
  const Model m = build_model(parse_scene(mesh_scene("cube_tetgen.node", R"(, "mls": {"volumes": "mesh", "neighbors": 4}, "fixed": [])"),
                                          "inline", kData));
  EXPECT_EQ(m.particle_count, 9);
  EXPECT_NEAR(m.total_volume, 1.0, 1e-15);
}

TEST(MeshScene, WithoutABoxTheMeshKeepsItsShape) {
  const Scene scene = parse_scene(mesh_scene("cube_tet_small.msh", R"(, "mls": {"volumes": "mesh"})", ""), "inline", kData);
  EXPECT_FALSE(scene.box_given);
  const Model m = build_model(scene);
  const TetMesh mesh = read_mesh(kData / "cube_tet_small.msh");
  EXPECT_NEAR(m.box_volume, mesh.total_volume, 1e-15);  // the mesh's own volume
  EXPECT_TRUE(parse_scene(mesh_scene("cube_tet_small.msh"), "inline", kData).box_given);
  // Lattices keep the (default) box.
  EXPECT_TRUE(parse_scene(R"({"body": {"distribution": {"type": "grid"}}})", "inline", kData).box_given);
}

TEST(MeshScene, ReaderErrorsNameTheFileAndLine) {
  const fs::path dir = fs::temp_directory_path() / ("palpate-mesh-bad-" + std::to_string(getpid()));
  fs::create_directories(dir);
  std::ofstream(dir / "bad.msh") << "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 x\n";
  try {
    build_model(parse_scene(mesh_scene("bad.msh"), "inline", dir));
    ADD_FAILURE() << "accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), (dir / "bad.msh").string() + ":5: numNodes: expected an integer, got 'x'");
  }
  fs::remove_all(dir);
}


// ---------------------------------------------------------------------------
// Physical groups, regions and the boundary faces.

// The unit cube of kGmsh41 with its bottom face (z = 0: nodes 1 2 3 4) in the physical
// surface 7 "bottom" (through $Entities) and the volume in physical volume 5 "tissue".
const std::string kGmsh41Groups = R"($MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
2
2 7 "bottom"
3 5 "tissue"
$EndPhysicalNames
$Entities
0 0 1 1
1 0 0 0 1 1 0 1 7 0
1 0 0 0 1 1 1 1 5 1 1
$EndEntities
$Nodes
1 8 1 8
3 1 0 8
1
2
3
4
5
6
7
8
0 0 0
1 0 0
0 1 0
1 1 0
0 0 1
1 0 1
0 1 1
1 1 1
$EndNodes
$Elements
2 8 1 8
2 1 2 2
1 1 2 4
2 1 4 3
3 1 4 6
3 1 2 4 8
4 1 6 2 8
5 1 4 3 8
6 1 3 7 8
7 1 5 6 8
8 1 7 5 8
$EndElements
)";

// The same in 2.2: an element's first tag is its physical group.
const std::string kGmsh22Groups = R"($MeshFormat
2.2 0 8
$EndMeshFormat
$PhysicalNames
2
2 7 "bottom"
3 5 "tissue"
$EndPhysicalNames
$Nodes
8
1 0 0 0
2 1 0 0
3 0 1 0
4 1 1 0
5 0 0 1
6 1 0 1
7 0 1 1
8 1 1 1
$EndNodes
$Elements
8
1 2 2 7 1 1 2 4
2 2 2 7 1 1 4 3
3 4 2 5 1 1 2 4 8
4 4 2 5 1 1 6 2 8
5 4 2 5 1 1 4 3 8
6 4 2 5 1 1 3 7 8
7 4 2 5 1 1 5 6 8
8 4 2 5 1 1 7 5 8
$EndElements
)";

TEST_F(MeshFiles, PhysicalSurfaceGroupsAndRegionsIn41And22) {
  for (const auto& [name, text] : {std::pair{"g41.msh", kGmsh41Groups}, std::pair{"g22.msh", kGmsh22Groups}}) {
    SCOPED_TRACE(name);
    const fs::path file = write(name, text);
    const TetMesh m = read_gmsh(file);
    EXPECT_EQ(m.ignored_elements, 2);  // the triangles are no particles' elements
    ASSERT_EQ(m.surface_groups.size(), 1u);
    EXPECT_EQ(m.surface_groups[0].tag, 7);
    EXPECT_EQ(m.surface_groups[0].name, "bottom");
    EXPECT_EQ(surface_group_nodes(m, file, "bottom"), (std::vector<int>{0, 1, 2, 3}));
    for (int i : m.surface_groups[0].nodes) EXPECT_EQ(m.positions(2, i), 0.0);
    EXPECT_EQ(m.tetrahedron_region, std::vector<int64_t>(6, 5));
    EXPECT_EQ(physical_group_tag(m, file, 3, "tissue"), 5);
    try {
      surface_group_nodes(m, file, "top");
      ADD_FAILURE() << "an unknown group was accepted";
    } catch (const std::runtime_error& e) {
      EXPECT_EQ(std::string(e.what()),
                file.string() + ": no physical group of dimension 2 is named 'top' (the file names 'bottom')");
    }
  }
  // Without physical tags on the elements: region 0, no groups (kGmsh22's triangles have tag 0).
  const TetMesh plain = read_gmsh(write("plain.msh", kGmsh22));
  EXPECT_TRUE(plain.surface_groups.empty());
  EXPECT_EQ(plain.tetrahedron_region, std::vector<int64_t>(6, 1));
  const TetMesh no_entity = read_gmsh(write("plain41.msh", kGmsh41));
  EXPECT_TRUE(no_entity.surface_groups.empty());  // its triangles' entity (2, 1) has no physical tag
  EXPECT_EQ(no_entity.tetrahedron_region, std::vector<int64_t>(6, 1));
}

TEST_F(MeshFiles, TetGenRegionAttribute) {
  write("plain.ele", tetgen_ele(1));
  EXPECT_EQ(read_tetgen(write("plain.node", tetgen_node(1))).tetrahedron_region, std::vector<int64_t>(6, 0));
  // One region attribute: tetrahedra 1-3 in region 4, 4-6 in region -2.
  std::string ele = tetgen_ele(1);
  std::istringstream in(ele);
  std::ostringstream out;
  std::string line;
  std::getline(in, line);
  out << "6 4 1\n";
  for (int t = 0; std::getline(in, line); ++t) out << line << (t < 3 ? " 4" : " -2.0") << '\n';
  write("regions.ele", out.str());
  EXPECT_EQ(read_tetgen(write("regions.node", tetgen_node(1))).tetrahedron_region,
            (std::vector<int64_t>{4, 4, 4, -2, -2, -2}));
}

// The boundary of a closed polyhedral surface: the area and, by the divergence theorem
// (the field x / 3 has divergence 1), sum_t (1/3) (x_t . n_t) A_t = the enclosed volume, with
// x_t any point of the triangle (its centroid) and n_t the unit outward normal: an inward
// triangle would subtract its share, so the identity checks the orientation.
struct SurfaceSums {
  double area = 0, volume = 0;
};
SurfaceSums surface_sums(const Points& X, const std::vector<std::array<int, 3>>& faces) {
  SurfaceSums s;
  for (const auto& f : faces) {
    const Vec3 a = X.col(f[0]), b = X.col(f[1]), c = X.col(f[2]);
    const Vec3 n2 = (b - a).cross(c - a);  // 2 A n
    s.area += 0.5 * n2.norm();
    s.volume += ((a + b + c) / 3.0).dot(n2) / 6.0;
  }
  return s;
}

TEST_F(MeshFiles, BoundaryFacesOfTheTetCube) {
  const TetMesh m = read_gmsh(write("cube.msh", kGmsh41));
  EXPECT_EQ(m.boundary_faces.size(), 12u);  // two triangles per cube face
  const SurfaceSums s = surface_sums(m.positions, m.boundary_faces);
  EXPECT_NEAR(s.area, 6.0, 1e-14);
  EXPECT_NEAR(s.volume, 1.0, 1e-14);
  for (const auto& f : m.boundary_faces)
    for (int v : f) EXPECT_TRUE(v >= 0 && v < m.positions.cols());
  // The committed gmsh cube (finer, shifted): the same identities, area 6 x its faces.
  const TetMesh fine = read_mesh(kData / "cube_tet_small.msh");
  const Vec3 edge = fine.positions.rowwise().maxCoeff() - fine.positions.rowwise().minCoeff();
  const SurfaceSums t = surface_sums(fine.positions, fine.boundary_faces);
  EXPECT_NEAR(t.area, 2 * (edge[0] * edge[1] + edge[1] * edge[2] + edge[2] * edge[0]), 1e-12);
  EXPECT_NEAR(t.volume, fine.total_volume, 1e-12 * fine.total_volume);
  // A mirrored TetGen file (stored reoriented) bounds the same volume outward.
  write("m.ele", tetgen_ele(1, false, true));
  const TetMesh mirrored = read_tetgen(write("m.node", tetgen_node(1)));
  EXPECT_NEAR(surface_sums(mirrored.positions, mirrored.boundary_faces).volume, 1.0, 1e-14);
}

// tests/data/dome.msh (tests/data/dome.geo): a hemisphere of radius 0.05 m on z = 0.
TEST(MeshData, TheDomeHasItsGroupsAndAClosedOutwardBoundary) {
  const fs::path file = kData / "dome.msh";
  const TetMesh m = read_mesh(file);
  EXPECT_GE(m.positions.cols(), 200);
  EXPECT_LE(m.positions.cols(), 2000);
  const std::vector<int>& base = surface_group_nodes(m, file, "base");
  const std::vector<int>& skin = surface_group_nodes(m, file, "skin");
  ASSERT_FALSE(base.empty());
  ASSERT_FALSE(skin.empty());
  for (int i : base) EXPECT_NEAR(m.positions(2, i), 0.0, 1e-12);
  for (int i : skin) EXPECT_NEAR(m.positions.col(i).norm(), 0.05, 1e-9);
  const int64_t tissue = physical_group_tag(m, file, 3, "tissue");
  for (int64_t r : m.tetrahedron_region) EXPECT_EQ(r, tissue);
  // Outward and closed: the divergence theorem gives the tetrahedra's volume, which lies
  // below the hemisphere's (2/3) pi R^3 by the chords' error (within a few per cent here).
  const SurfaceSums s = surface_sums(m.positions, m.boundary_faces);
  EXPECT_NEAR(s.volume, m.total_volume, 1e-12);
  const double hemisphere = 2.0 / 3.0 * M_PI * std::pow(0.05, 3);
  EXPECT_LT(m.total_volume, hemisphere);
  EXPECT_GT(m.total_volume, 0.95 * hemisphere);
  EXPECT_LT(s.area, 3 * M_PI * 0.05 * 0.05);  // the base pi R^2 plus the cap 2 pi R^2, from inside
  EXPECT_GT(s.area, 0.95 * 3 * M_PI * 0.05 * 0.05);
  // Every boundary node belongs to a group, and the groups' nodes are boundary nodes.
  std::vector<char> on_boundary(m.positions.cols(), 0), grouped(m.positions.cols(), 0);
  for (const auto& f : m.boundary_faces)
    for (int v : f) on_boundary[v] = 1;
  for (int i : base) grouped[i] = 1;
  for (int i : skin) grouped[i] = 1;
  EXPECT_EQ(on_boundary, grouped);
}

}  // namespace
}  // namespace palpate
