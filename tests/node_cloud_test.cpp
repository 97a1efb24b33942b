// Node distributions, k-nearest-neighbour support domains and face selection.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "core/boundary.h"
#include "core/neighbors.h"
#include "core/node_cloud.h"

namespace palpate {
namespace {

BoxSpec unit_box() {
  BoxSpec b;
  b.min = Vec3(0, 0, 0);
  b.max = Vec3(2, 1, 1);
  return b;
}

TEST(NodeCloud, GridByCountAndBySpacing) {
  const NodeCloud c = grid_nodes(unit_box(), Eigen::Vector3i(5, 3, 4));
  EXPECT_EQ(c.positions.cols(), 60);
  EXPECT_EQ(c.positions.rowwise().minCoeff(), Vec3(0, 0, 0));
  EXPECT_EQ(c.positions.rowwise().maxCoeff(), Vec3(2, 1, 1));
  double volume = 0;
  for (double v : c.lattice_volume) volume += v;
  EXPECT_NEAR(volume, 2.0, 1e-12);
  EXPECT_EQ(nodes_per_axis(unit_box(), 0.25), Eigen::Vector3i(9, 5, 5));
}

TEST(NodeCloud, GradedAxisIsGeometricFromTheFocus) {
  // One-sided (focus on an end): first interval = s, constant ratio, ends exact.
  const std::vector<double> z = graded_axis(-2.0, 0.0, 0.0, 21, 0.025);
  ASSERT_EQ(z.size(), 21u);
  EXPECT_DOUBLE_EQ(z.front(), -2.0);
  EXPECT_DOUBLE_EQ(z.back(), 0.0);
  EXPECT_NEAR(z[20] - z[19], 0.025, 1e-12);
  const double r = (z[19] - z[18]) / (z[20] - z[19]);
  EXPECT_GT(r, 1.0);
  for (int k = 1; k + 1 < 20; ++k) EXPECT_NEAR((z[k] - z[k - 1]) / (z[k + 1] - z[k]), r, 1e-9);
  // Two-sided, focus in the middle: a node on the focus, symmetric spacings.
  const std::vector<double> x = graded_axis(-1.0, 1.0, 0.0, 21, 0.025);
  EXPECT_DOUBLE_EQ(x[10], 0.0);
  for (int k = 0; k < 21; ++k) EXPECT_NEAR(x[k], -x[20 - k], 1e-12);
  EXPECT_NEAR(x[11] - x[10], 0.025, 1e-12);
  EXPECT_THROW(graded_axis(0.0, 1.0, 0.0, 5, 2.0), std::invalid_argument);
  EXPECT_THROW(graded_axis(0.0, 1.0, 1.5, 5, 0.1), std::invalid_argument);
}

TEST(NodeCloud, GradedGridVolumesFillTheBox) {
  BoxSpec box;  // the default 2 m cube, top face at z = 0
  const NodeCloud c = graded_grid_nodes(box, Eigen::Vector3i(15, 15, 15), Vec3(0, 0, 0), 0.03);
  EXPECT_EQ(c.lattice_size, Eigen::Vector3i(15, 15, 15));
  double volume = 0;
  for (double v : c.lattice_volume) volume += v;
  EXPECT_NEAR(volume, 8.0, 1e-12);
  // The node nearest the focus is the focus itself, its neighbour 0.03 m away.
  const Eigen::Index centre = 7 + 15 * (7 + 15 * 14);
  EXPECT_NEAR(c.positions.col(centre).norm(), 0.0, 1e-12);
  EXPECT_NEAR((c.positions.col(centre + 1) - c.positions.col(centre)).norm(), 0.03, 1e-12);
}

TEST(NodeCloud, JitteredGridIsSeededBoundedAndKeepsFaces) {
  const Eigen::Vector3i n(9, 5, 5);
  const NodeCloud base = grid_nodes(unit_box(), n);
  const NodeCloud a = jittered_grid_nodes(unit_box(), n, 0.3, 42);
  const NodeCloud b = jittered_grid_nodes(unit_box(), n, 0.3, 42);
  const NodeCloud c = jittered_grid_nodes(unit_box(), n, 0.3, 43);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_NE(a.positions, c.positions);
  const double spacing = 0.25;
  const Points diff = a.positions - base.positions;
  EXPECT_LE(diff.cwiseAbs().maxCoeff(), 0.3 * spacing + 1e-12);
  EXPECT_GT(diff.cwiseAbs().maxCoeff(), 0.1 * spacing);
  // Nodes on a face stay on it (the box is unchanged).
  EXPECT_EQ(a.positions.rowwise().minCoeff(), Vec3(0, 0, 0));
  EXPECT_EQ(a.positions.rowwise().maxCoeff(), Vec3(2, 1, 1));
}

TEST(NodeCloud, NodeListLoaderReadsAndRejectsWithLineNumbers) {
  const auto dir = std::filesystem::temp_directory_path();
  const auto good = dir / "palpate_nodes_good.txt";
  const auto bad = dir / "palpate_nodes_bad.txt";
  {
    std::ofstream out(good);
    out << "# corners of the unit cube\n";
    for (int k = 0; k < 8; ++k) out << (k & 1) << " " << ((k >> 1) & 1) << " " << ((k >> 2) & 1) << "\n";
    out << "\n0.5 0.5 0.5\n";
    std::ofstream out2(bad);
    out2 << "0 0 0\n1 0 0\n1 oops 0\n";
  }
  const NodeCloud c = load_node_list(good);
  EXPECT_EQ(c.positions.cols(), 9);
  EXPECT_EQ(c.positions.col(8), Vec3(0.5, 0.5, 0.5));
  try {
    load_node_list(bad);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("palpate_nodes_bad.txt:3"), std::string::npos) << e.what();
  }
  EXPECT_THROW(load_node_list(dir / "palpate_no_such_file.txt"), std::runtime_error);
  std::filesystem::remove(good);
  std::filesystem::remove(bad);
}

TEST(Neighbors, MatchBruteForceNearestFirst) {
  const NodeCloud c = jittered_grid_nodes(unit_box(), Eigen::Vector3i(9, 5, 5), 0.3, 5);
  const int k = 16, n = static_cast<int>(c.positions.cols());
  const Neighborhoods nb = k_nearest_neighbors(c.positions, k);
  ASSERT_EQ(nb.offset.back(), n * k);
  for (int i = 0; i < n; i += 13) {
    std::vector<double> d2;
    for (int j = 0; j < n; ++j)
      if (j != i) d2.push_back((c.positions.col(j) - c.positions.col(i)).squaredNorm());
    std::sort(d2.begin(), d2.end());
    for (int a = 0; a < k; ++a) {
      EXPECT_NE(nb.index[nb.offset[i] + a], i);
      EXPECT_NEAR(nb.dist2[nb.offset[i] + a], d2[a], 1e-12);
    }
  }
  EXPECT_THROW(k_nearest_neighbors(c.positions, n), std::invalid_argument);
}

TEST(Boundary, FacesSelectTheirParticles) {
  const int N = 6;
  BoxSpec box;
  const NodeCloud c = grid_nodes(box, Eigen::Vector3i::Constant(N));
  auto count = [&](uint32_t faces) {
    const auto on = particles_on_faces(c.positions, faces);
    return std::count(on.begin(), on.end(), 1);
  };
  EXPECT_EQ(count(face_bottom), N * N);
  EXPECT_EQ(count(face_top | face_bottom), 2 * N * N);
  // Bottom and four sides: everything but the (N-2)^2 (N-1) particles off those faces.
  EXPECT_EQ(count(face_bottom | faces_sides), N * N * N - (N - 2) * (N - 2) * (N - 1));
  EXPECT_EQ(count(0), 0);
}

}  // namespace
}  // namespace palpate
