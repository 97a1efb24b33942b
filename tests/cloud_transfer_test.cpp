// Carrying a deformed state between two refinements of one body (core/cloud_transfer.h),
// judged by what linear interpolation must do whatever the clouds: reproduce a linear
// (affine) displacement and velocity field exactly, copy coinciding particles, conserve the
// total contact force, and refuse a point that is not in the body.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "core/cloud_transfer.h"
#include "core/mesh_reader.h"
#include "core/model.h"
#include "core/node_cloud.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"

namespace palpate {
namespace {

namespace fs = std::filesystem;

struct Refocused {
  Scene scene;
  NodeCloud cloud;
  Model model;
};

Refocused at(double x, double y) {
  Refocused r;
  r.scene = load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_block_follow.json");
  r.scene.indenter.position_given = true;
  r.scene.indenter.position = Vec3(x, y, 0.0101);
  r.cloud = make_node_cloud(r.scene);
  r.model = build_model(r.scene, r.cloud);
  return r;
}

TEST(CloudTransfer, ReproducesAnAffineFieldExactly) {
  const Refocused a = at(0.0, 0.0), b = at(0.003, -0.002);
  ASSERT_NE(a.model.particle_count, b.model.particle_count);  // different clouds
  const CloudTransfer transfer = make_cloud_transfer(a.model.rest_position, a.cloud.tetrahedra, b.model.rest_position, b.cloud.tetrahedra);
  // The base's vertices at least coincide, and many midpoints both refinements made.
  const int base_vertices =
      static_cast<int>(read_mesh(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "meshes" / "palpation_block_base.msh").positions.cols());
  EXPECT_GT(transfer.exact, base_vertices);
  EXPECT_LT(transfer.exact, b.model.particle_count);
  EXPECT_GE(transfer.worst_outside, -1e-9);
  for (int i = 0; i < transfer.new_count; ++i) {
    double sum = 0;
    for (int k = transfer.offset[i]; k < transfer.offset[i + 1]; ++k) sum += transfer.weight[k];
    ASSERT_NEAR(sum, 1.0, 1e-12) << "row " << i;
  }
  // u(X) = G X + t and v(X) = H X + s on the old cloud (fixed particles too: the field is the truth).
  Mat3 G, H;
  G << 0.01, -0.02, 0.005, 0.0, 0.03, -0.01, 0.02, 0.0, -0.04;
  H << -0.3, 0.1, 0.0, 0.2, 0.0, 0.5, 0.0, -0.1, 0.2;
  const Vec3 t(1e-4, -2e-4, -3e-4), s(0.01, 0.02, -0.03);
  const Options opt = options_of(a.scene);
  State old_state = make_state(a.model, opt);
  for (int i = 0; i < a.model.particle_count; ++i) {
    const Vec3 X = a.model.rest_position.col(i);
    old_state.position.col(i) = X + G * X + t;
    old_state.velocity.col(i) = H * X + s;
  }
  old_state.indenter_center = Vec3(0.001, 0.002, 0.0095);
  old_state.time = 1.25;
  old_state.tick = 2500;
  State new_state = make_state(b.model, options_of(b.scene));
  transfer_state(transfer, a.model, old_state, b.model, new_state);
  for (int i = 0; i < b.model.particle_count; ++i) {
    const Vec3 X = b.model.rest_position.col(i);
    if (b.model.fixed[i]) {
      EXPECT_EQ(new_state.position.col(i), X);
      continue;
    }
    ASSERT_LT((new_state.position.col(i) - (X + G * X + t)).norm(), 1e-15) << "particle " << i;
    ASSERT_LT((new_state.velocity.col(i) - (H * X + s)).norm(), 1e-14) << "particle " << i;
  }
  EXPECT_EQ(new_state.indenter_center, old_state.indenter_center);
  EXPECT_EQ(new_state.time, 1.25);
  EXPECT_EQ(new_state.tick, 2500);
}

TEST(CloudTransfer, KeepsTheTotalContactForce) {
  const Refocused a = at(0.01, 0.0), b = at(0.0115, 0.0);
  const CloudTransfer transfer = make_cloud_transfer(a.model.rest_position, a.cloud.tetrahedra, b.model.rest_position, b.cloud.tetrahedra);
  State old_state = make_state(a.model, options_of(a.scene));
  // A contact set: the free particles within 4 mm of (10, 0, 0) mm, pushed down and outward.
  Vec3 total = Vec3::Zero();
  for (int i = 0; i < a.model.particle_count; ++i) {
    const Vec3 X = a.model.rest_position.col(i);
    if (a.model.fixed[i] || (X - Vec3(0.01, 0, 0)).norm() > 0.004) continue;
    const int k = static_cast<int>(old_state.contact_index.size());
    old_state.contact_index.push_back(i);
    old_state.contact_force.col(k) = Vec3(0.1 * (X.x() - 0.01), 0.1 * X.y(), -0.01);
    old_state.contact_normal_force.push_back(0.01);
    total += old_state.contact_force.col(k);
  }
  ASSERT_GT(old_state.contact_index.size(), 10u);
  State new_state = make_state(b.model, options_of(b.scene));
  transfer_state(transfer, a.model, old_state, b.model, new_state);
  Vec3 carried = Vec3::Zero();
  for (size_t k = 0; k < new_state.contact_index.size(); ++k) carried += new_state.contact_force.col(static_cast<Eigen::Index>(k));
  EXPECT_LT((carried - total).norm(), 1e-12 * total.norm());
  EXPECT_GE(new_state.contact_index.size(), old_state.contact_index.size() / 2);
  // The scratch is left clean: a second transfer gives the same.
  State again = make_state(b.model, options_of(b.scene));
  transfer_state(transfer, a.model, old_state, b.model, again);
  EXPECT_EQ(again.contact_index, new_state.contact_index);
}

// A curved body: the dome's cloud refined at its pole and on its flank. Each refinement's new
// skin vertices lie on the sphere (physics.md (7.1a)), so some lie outside the other cloud's
// coarser facets, by up to their sag; they are extrapolated from the nearest tetrahedron,
// which an affine field survives exactly, both ways.
TEST(CloudTransfer, ACurvedBodysSurfaceVerticesOutsideTheOtherCloudsFacetsAreExtrapolated) {
  auto dome_at = [](double x, double y) {
    Refocused r;
    r.scene = load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_dome_follow.json");
    r.scene.indenter.position_given = true;
    // A quarter of the radius out along the skin's normal: the refinement's focus is that point of the skin.
    r.scene.indenter.position = 1.25 * Vec3(x, y, std::sqrt(0.05 * 0.05 - x * x - y * y));
    r.cloud = make_node_cloud(r.scene);
    r.model = build_model(r.scene, r.cloud);
    return r;
  };
  const Refocused a = dome_at(0.0, 0.0), b = dome_at(0.012, 0.005);
  const CloudTransfer there =
      make_cloud_transfer(a.model.rest_position, a.cloud.tetrahedra, b.model.rest_position, b.cloud.tetrahedra);
  EXPECT_LT(there.worst_outside, -1e-6);  // the flank's new skin vertices, outside the pole cloud's facets
  EXPECT_GT(there.worst_outside, -0.05);
  Mat3 G;
  G << 0.01, -0.02, 0.005, 0.0, 0.03, -0.01, 0.02, 0.0, -0.04;
  const Vec3 t(1e-4, -2e-4, -3e-4);
  State old_state = make_state(a.model, options_of(a.scene));
  for (int i = 0; i < a.model.particle_count; ++i) {
    const Vec3 X = a.model.rest_position.col(i);
    old_state.position.col(i) = X + G * X + t;
  }
  State new_state = make_state(b.model, options_of(b.scene));
  transfer_state(there, a.model, old_state, b.model, new_state);
  for (int i = 0; i < b.model.particle_count; ++i) {
    const Vec3 X = b.model.rest_position.col(i);
    if (!b.model.fixed[i]) {
      ASSERT_LT((new_state.position.col(i) - (X + G * X + t)).norm(), 1e-15) << "particle " << i;
    }
  }
}

TEST(CloudTransfer, RefusesAPointOutsideTheBody) {
  const Refocused a = at(0.0, 0.0);
  Points outside(3, 1);
  outside.col(0) = Vec3(0.0, 0.0, 0.001);  // 1 mm above the top face
  EXPECT_THROW(make_cloud_transfer(a.model.rest_position, a.cloud.tetrahedra, outside, a.cloud.tetrahedra), std::invalid_argument);
}

}  // namespace
}  // namespace palpate
