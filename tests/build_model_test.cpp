// Model construction: node files, diagnostics, the indenter's placement and
// the errors a scene that cannot be built gets.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/mls_forces.h"
#include "core/node_cloud.h"
#include "test_util.h"

namespace palpate {
namespace {

TEST(BuildModel, NodeFileCloudBuildsWithKernelVolumes) {
  // Write a jittered lattice as a plain node list and build from it.
  BoxSpec box;
  box.min = Vec3(0, 0, 0);
  box.max = Vec3(1, 1, 1);
  const NodeCloud cloud = jittered_grid_nodes(box, Eigen::Vector3i::Constant(6), 0.2, 9);
  const auto dir = std::filesystem::temp_directory_path() / "palpate_build_model_test";
  std::filesystem::create_directories(dir);
  {
    std::ofstream out(dir / "nodes.txt");
    out.precision(17);
    for (int i = 0; i < cloud.positions.cols(); ++i)
      out << cloud.positions(0, i) << ' ' << cloud.positions(1, i) << ' ' << cloud.positions(2, i) << '\n';
  }
  const Scene scene = parse_scene(
      R"({"body": {"box": {"min": [0,0,0], "max": [1,1,1]}, "distribution": {"type": "node_file", "node_file": "nodes.txt"}},
          "mls": {"neighbors": 16, "support_factor": 1.5}})",
      "inline", dir);
  const Model m = build_model(scene);
  EXPECT_EQ(m.particle_count, 216);
  EXPECT_EQ(m.rest_position, cloud.positions);
  EXPECT_EQ(m.regularized_count, 0);
  EXPECT_EQ(m.fixed_count, 216 - 4 * 4 * 5);  // bottom and sides of a 6^3 lattice
  // The indenter starts centred, resting on the particles; indentation counts from the
  // sphere touching the top surface (the highest particle under it, z = 1 here).
  EXPECT_NEAR(m.indenter_start[0], 0.5, 1e-12);
  EXPECT_NEAR(m.touch_height - m.indenter_radius, 1.0, 1e-12);
  EXPECT_LE(m.indenter_start[2], m.touch_height);
  // The MLS gradient reproduces a linear field here as well.
  Mat3 G = Mat3::Identity() * 0.01;
  G(0, 2) = 0.02;
  Points x(3, m.particle_count);
  for (int i = 0; i < m.particle_count; ++i) x.col(i) = m.rest_position.col(i) + G * m.rest_position.col(i);
  for (int i = 0; i < m.particle_count; ++i)
    EXPECT_LT((deformation_gradient(m, x, i) - (Mat3::Identity() + G)).norm(), 1e-11);
  std::filesystem::remove_all(dir);
}

TEST(BuildModel, SceneThatCannotBeBuiltNamesTheField) {
  auto field_of = [](const std::string& json) {
    try {
      test::model_from_json(json);
    } catch (const SceneError& e) {
      return e.field();
    }
    return std::string("no error");
  };
  EXPECT_EQ(field_of(R"({"body": {"distribution": {"per_edge": 2}}, "mls": {"neighbors": 16}})"), "/mls/neighbors");
  EXPECT_EQ(field_of(R"({"indenter": {"position": [5, 5, 1]}})"), "/indenter/position");   // not above the body
  EXPECT_EQ(field_of(R"({"body": {"distribution": {"per_edge": 5}}, "indenter": {"position": [0, 0, 0.2]}})"),
            "/indenter/position");  // inside the body
}

TEST(BuildModel, PaperVolumesAreReportedAgainstTheBox) {
  const Model kernel = test::model_from_json(R"({"body": {"distribution": {"per_edge": 8}}, "mls": {"volumes": "kernel"}})");
  const Model lattice = test::model_from_json(R"({"body": {"distribution": {"per_edge": 8}}, "mls": {"volumes": "lattice"}})");
  EXPECT_NEAR(lattice.total_volume, 8.0, 1e-12);
  EXPECT_NEAR(kernel.box_volume, 8.0, 1e-12);
  EXPECT_GT(kernel.total_volume, lattice.total_volume);  // boundary particles get more than their share
  double mass = 0;
  for (double v : lattice.mass) mass += v;
  EXPECT_NEAR(mass, 8000.0, 1e-9);
}

}  // namespace
}  // namespace palpate
