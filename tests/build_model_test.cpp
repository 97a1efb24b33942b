// Model construction: node files, diagnostics, the indenter's placement and
// the errors a scene that cannot be built gets.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>

#include "analysis/rest.h"
#include "core/mesh_reader.h"
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

// The mass floor (docs/physics.md (1.18)) on the cloud it was made for: the palpation block
// refined by bisection toward a site near a corner, scenes/palpation_block_follow.json.
namespace mass_floor {

namespace fs = std::filesystem;
const fs::path kFollowScene = fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_block_follow.json";

// The scene refined toward (x, y) on its top face, the tool just above it on the vertical
// guide (the Hertz experiment), with mls.mass_floor = beta (and integrator.damping = damping,
// 1/s, when given).
test::Setup at_site(double x, double y, double beta, std::optional<double> damping = std::nullopt) {
  // One rate: the subcycled scene's blocks follow its masses (core/rate_schedule.h), and the
  // forces are compared bit for bit below.
  SceneOverrides overrides = {{"mls.mass_floor", std::to_string(beta)}, {"indenter.guide", "\"vertical\""},
                              {"integrator.max_interval", "1"}};
  if (damping) overrides.emplace_back("integrator.damping", std::to_string(*damping));
  Scene scene = load_scene(kFollowScene, overrides);
  scene.indenter.position_given = true;
  scene.indenter.position = Vec3(x, y, scene.indenter.radius * 1.01);
  return test::setup_from(scene);
}

TEST(MassFloor, RaisesTheLightParticlesToTheFloorAndNothingElse) {
  const test::Setup off = at_site(0.035, -0.035, 0.0), on = at_site(0.035, -0.035, 0.5);
  const Model &a = off.model, &b = on.model;
  ASSERT_EQ(a.particle_count, b.particle_count);
  EXPECT_EQ(a.mass_floor_raised, 0);
  int raised = 0;
  double added = 0.0;
  for (int i = 0; i < a.particle_count; ++i) {
    double sum = 0.0;
    for (int k = a.neighbor_offset[i]; k < a.neighbor_offset[i + 1]; ++k) sum += a.mass[a.neighbor_index[k]];
    const double floor = 0.5 * sum / (a.neighbor_offset[i + 1] - a.neighbor_offset[i]);
    ASSERT_DOUBLE_EQ(b.mass[i], std::max(a.mass[i], floor)) << "particle " << i;
    ASSERT_EQ(b.volume[i], a.volume[i]) << "particle " << i;
    raised += a.mass[i] < floor;
    added += b.mass[i] - a.mass[i];
  }
  EXPECT_GT(raised, 0);
  EXPECT_EQ(b.mass_floor_raised, raised);
  EXPECT_NEAR(b.mass_floor_added, added, 1e-12 * added);
  // Forces depend on volumes, not masses: the same at any configuration, bit for bit.
  Points x = a.rest_position, fa(3, a.particle_count), fb(3, a.particle_count);
  for (int i = 0; i < a.particle_count; ++i) x(2, i) -= 1e-4 * std::exp(-(x.col(i) - Vec3(0.035, -0.035, 0)).squaredNorm() / 1e-4);
  WorkerThreads threads(1, a.particle_count);
  mls_internal_forces(a, x, fa, threads);
  mls_internal_forces(b, x, fb, threads);
  EXPECT_EQ(fa, fb);
}

// Statics does not depend on mass: the depth at rest is the same with the floor and without
// (at the centre, where both come to rest); and near the corner, where the vertex at the
// focus is the lightest particle, only the floor comes to rest at dt 1 ms with the damping of
// 20 1/s the floor was made for (without it, that particle oscillated in contact for the 60 s
// of a press; the scene's 80 1/s alone brings it to rest, in 1310 steps).
TEST(MassFloor, KeepsTheRestDepthAndBringsTheFocusVertexToRest) {
  constexpr double kForce = 0.262;  // N, the scene's largest verification force
  constexpr double kDamping = 20.0;  // 1/s
  auto press = [&](double x, double y, double beta, double max_time) {
    test::Setup s = at_site(x, y, beta, kDamping);
    RestSpec rest = s.scene.verify.rest;
    rest.max_time = max_time;
    State state = make_state(s.model, s.opt);
    return press_to_rest(s.model, s.opt, rest, state, kForce);
  };
  const PressResult centre_off = press(0.0, 0.0, 0.0, 10.0), centre_on = press(0.0, 0.0, 0.5, 10.0);
  ASSERT_TRUE(centre_off.at_rest);
  ASSERT_TRUE(centre_on.at_rest);
  EXPECT_NEAR(centre_on.indentation / centre_off.indentation, 1.0, 1e-3);

  const PressResult corner_on = press(0.035, -0.035, 0.5, 10.0);
  EXPECT_TRUE(corner_on.at_rest);
  EXPECT_LT(corner_on.steps, 2000);
  const PressResult corner_off = press(0.035, -0.035, 0.0, 3.0);  // the control: the same press without it
  EXPECT_FALSE(corner_off.at_rest) << "came to rest in " << corner_off.steps << " steps without the floor";
}

// Hourglass control on a cloud refined in-process (docs/physics.md (1.9)): kappa_i only where the
// support holds a particle the refinement added, checked against the base mesh's vertex count
// read from its file; and the blocked loops, which skip the blocks without it, give the
// per-particle reference loops' forces and force differentials.
TEST(HourglassWhereRefined, OnlyNearTheRefinementAndTheBlockedLoopsMatchTheReference) {
  const test::Setup s = at_site(0.0175, 0.0, 0.5);
  const Model& m = s.model;
  const int n = m.particle_count;
  const int base = static_cast<int>(read_mesh(s.scene.distribution.mesh_file).positions.cols());
  ASSERT_GT(n, base);
  int with = 0;
  for (int i = 0; i < n; ++i) {
    bool near = i >= base, has = false;
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      near = near || m.neighbor_index[a] >= base;
      has = has || m.hourglass_weight[a] != 0;
    }
    ASSERT_EQ(has, near) << "particle " << i;
    with += has;
  }
  EXPECT_GT(with, n / 4);
  EXPECT_LT(with, n - n / 4);  // on this cloud about half the particles have none
  int skipped = 0;
  for (const auto& block : m.block_hourglass) skipped += !block.active;
  EXPECT_GT(skipped, 0) << "no block without hourglass control: the loops skip nothing";

  Model reference = m;
  reference.blocks.clear();
  ASSERT_TRUE(detail::uses_blocked_loops(m));
  ASSERT_FALSE(detail::uses_blocked_loops(reference));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1e-4, 1e-4);  // m: a tenth of the finest spacing
  Points x = m.rest_position, dx(3, n);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) {
      if (!m.fixed[i]) x(c, i) += u(rng);
      dx(c, i) = u(rng);
    }
  Points f(3, n), f_reference(3, n);
  mls_internal_forces(m, x, f);
  mls_internal_forces(reference, x, f_reference);
  EXPECT_LT((f - f_reference).cwiseAbs().maxCoeff(), 1e-12 * f_reference.cwiseAbs().maxCoeff());
  std::vector<double> F, S;
  mls_linearize(m, x, F, S);
  Points df(3, n), df_reference(3, n);
  mls_force_differential(m, F, S, dx, df);
  mls_force_differential(reference, F, S, dx, df_reference);
  EXPECT_LT((df - df_reference).cwiseAbs().maxCoeff(), 1e-12 * df_reference.cwiseAbs().maxCoeff());
}

}  // namespace mass_floor

}  // namespace
}  // namespace palpate
