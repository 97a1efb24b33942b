// The boundary surface (core/surface.h, Model::surface_triangles) and the sphere's first
// contact with it (docs/physics.md (2.16)): closed, outward surfaces whose area and
// enclosed volume (divergence theorem) are known; contact heights against analytic values
// and a dense sampling of the triangles.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <map>
#include <utility>

#include "core/mesh_reader.h"
#include "core/model.h"
#include "core/node_cloud.h"
#include "core/options.h"
#include "core/state.h"
#include "core/step.h"
#include "core/scene.h"
#include "core/surface.h"

namespace palpate {
namespace {

namespace fs = std::filesystem;
const fs::path kData = fs::path(PALPATE_SOURCE_DIR) / "tests" / "data";

struct Sums {
  double area = 0, volume = 0;
};
// Area and, by the divergence theorem (div x/3 = 1), sum_t (1/3) (x_t . n_t) A_t: the enclosed
// volume when every triangle faces outward (an inward one subtracts its share).
Sums sums(const Points& X, const SurfaceTriangles& tri) {
  Sums s;
  for (Eigen::Index t = 0; t < tri.cols(); ++t) {
    const Vec3 a = X.col(tri(0, t)), b = X.col(tri(1, t)), c = X.col(tri(2, t));
    const Vec3 n2 = (b - a).cross(c - a);
    s.area += 0.5 * n2.norm();
    s.volume += ((a + b + c) / 3.0).dot(n2) / 6.0;
  }
  return s;
}

// Every index valid; every edge in exactly two triangles, once in each direction (closed and
// consistently oriented).
void expect_closed(const SurfaceTriangles& tri, int n) {
  std::map<std::pair<int, int>, int> directed;
  for (Eigen::Index t = 0; t < tri.cols(); ++t)
    for (int a = 0; a < 3; ++a) {
      const int u = tri(a, t), v = tri((a + 1) % 3, t);
      ASSERT_TRUE(u >= 0 && u < n && v >= 0 && v < n);
      ++directed[{u, v}];
    }
  for (const auto& [edge, count] : directed) {
    EXPECT_EQ(count, 1) << edge.first << " -> " << edge.second;
    const auto back = directed.find({edge.second, edge.first});
    EXPECT_TRUE(back != directed.end() && back->second == 1) << edge.first << " - " << edge.second;
  }
}

TEST(LatticeSurface, ClosedOutwardWithTheBoxAreaAndVolume) {
  BoxSpec box;
  box.min = Vec3(-1, 0.5, -2);
  box.max = Vec3(2, 1.5, 0);
  const Vec3 e = box.max - box.min;
  const Eigen::Vector3i per_axis(5, 3, 4);
  const NodeCloud clouds[] = {grid_nodes(box, per_axis), jittered_grid_nodes(box, per_axis, 0.3, 7),
                              graded_grid_nodes(box, per_axis, Vec3(0.5, 1.0, 0.0), 0.2)};
  for (const NodeCloud& cloud : clouds) {
    const SurfaceTriangles tri = cloud_surface(cloud);
    EXPECT_EQ(tri.cols(), 4 * (4 * 2 + 2 * 3 + 3 * 4));  // two triangles per face cell, two faces per axis
    expect_closed(tri, static_cast<int>(cloud.positions.cols()));
    const Sums s = sums(cloud.positions, tri);
    EXPECT_NEAR(s.volume, e.prod(), 1e-12 * e.prod());
    if (&cloud != &clouds[1]) {  // a jittered lattice's side faces are not planar, their area larger
      EXPECT_NEAR(s.area, 2 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]), 1e-12);
    }
  }
  EXPECT_EQ(cloud_surface(NodeCloud{}).cols(), 0);  // a node list has no surface
}

// The contact height of one triangle by dense sampling: max over points p of p_z +
// sqrt(R^2 - r_p^2), r_p the horizontal distance from the axis (a lower bound converging
// as the sampling refines).
double sampled_contact(const Vec3& a, const Vec3& b, const Vec3& c, double cx, double cy, double R, int n) {
  double top = -INFINITY;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; i + j <= n; ++j) {
      const Vec3 p = a + (b - a) * (double(i) / n) + (c - a) * (double(j) / n);
      const double r2 = (p[0] - cx) * (p[0] - cx) + (p[1] - cy) * (p[1] - cy);
      if (r2 <= R * R) top = std::max(top, p[2] + std::sqrt(R * R - r2));
    }
  return top;
}

TEST(SphereContact, OneTriangleFaceEdgeAndVertexAgainstSampling) {
  Points X(3, 3);
  X.col(0) = Vec3(0, 0, 0);
  X.col(1) = Vec3(1, 0.1, 0.3);
  X.col(2) = Vec3(0.2, 0.9, -0.2);
  SurfaceTriangles tri(3, 1);
  tri << 0, 1, 2;
  const double R = 0.4;
  // Over the interior (face contact), beyond an edge (edge contact), beyond a corner (vertex).
  const std::pair<double, double> sites[] = {{0.4, 0.3}, {0.6, -0.25}, {-0.2, -0.2}, {1.2, 0.1}, {0.5, 0.7}};
  for (const auto& [cx, cy] : sites) {
    const double exact = sphere_first_contact_height(X, tri, cx, cy, R);
    const double sampled = sampled_contact(X.col(0), X.col(1), X.col(2), cx, cy, R, 1500);
    EXPECT_GE(exact, sampled - 1e-12) << cx << ", " << cy;
    EXPECT_NEAR(exact, sampled, 2e-4) << cx << ", " << cy;
  }
  // Footprint missing the triangle: no contact.
  EXPECT_EQ(sphere_first_contact_height(X, tri, 3.0, 3.0, R), -INFINITY);
}

// A flat top gives Z_top + R to round-off, wherever the axis meets it (node, edge, cell).
TEST(SphereContact, FlatTopIsTheTopPlusTheRadius) {
  BoxSpec box;
  const NodeCloud cloud = grid_nodes(box, Eigen::Vector3i(7, 7, 4));
  const SurfaceTriangles tri = cloud_surface(cloud);
  const double R = 0.5;
  for (const auto& [cx, cy] : {std::pair{0.0, 0.0}, {1.0 / 3, 0.0}, {0.1, 0.2}, {-0.77, 0.31}, {0.5, 0.5}})
    EXPECT_NEAR(sphere_first_contact_height(cloud.positions, tri, cx, cy, R), box.max[2] + R, 1e-15)
        << cx << ", " << cy;
}

// The dome (tests/data/dome.msh): a hemisphere of radius Rb = 0.05 m centred at the origin.
// Its skin triangles are chords of the sphere, so the body lies inside the ball of radius Rb:
// a sphere of radius R over lateral offset d first touches that ball (on its upper half) at
// z = sqrt((Rb + R)^2 - d^2), an upper bound. The surface's vertices lie on the sphere, and
// the first contact is at least the highest contact with a vertex, max_v z_v + sqrt(R^2 - r_v^2)
// (computed here from the positions alone), a lower bound; the two differ by the chords'
// sag, Lmax^2 / (8 Rb) for the longest skin edge Lmax. At the pole (a vertex, d = 0) the
// contact is exactly the pole + R.
TEST(SphereContact, DomeBetweenItsSphereAndItsVertices) {
  const fs::path file = kData / "dome.msh";
  const TetMesh mesh = read_mesh(file);
  SurfaceTriangles tri(3, static_cast<Eigen::Index>(mesh.boundary_faces.size()));
  for (size_t t = 0; t < mesh.boundary_faces.size(); ++t)
    for (int a = 0; a < 3; ++a) tri(a, static_cast<Eigen::Index>(t)) = mesh.boundary_faces[t][a];
  const Points& X = mesh.positions;
  expect_closed(tri, static_cast<int>(X.cols()));
  const double Rb = 0.05;
  double longest = 0;
  for (Eigen::Index t = 0; t < tri.cols(); ++t)
    for (int a = 0; a < 3; ++a) longest = std::max(longest, (X.col(tri(a, t)) - X.col(tri((a + 1) % 3, t))).norm());
  const double sag = longest * longest / (8 * Rb);
  int pole = 0;
  for (Eigen::Index i = 0; i < X.cols(); ++i)
    if (X(2, i) > X(2, pole)) pole = static_cast<int>(i);
  ASSERT_NEAR(X(0, pole), 0.0, 1e-12);
  ASSERT_NEAR(X(1, pole), 0.0, 1e-12);
  for (double R : {0.005, 0.02}) {
    EXPECT_NEAR(sphere_first_contact_height(X, tri, X(0, pole), X(1, pole), R), X(2, pole) + R, 1e-15);
    for (double s : {0.004, 0.011, 0.023, 0.031}) {
      const double cx = s, cy = 0.3 * s, d = std::hypot(cx, cy);
      const double z = sphere_first_contact_height(X, tri, cx, cy, R);
      const double upper = std::sqrt((Rb + R) * (Rb + R) - d * d);
      double lower = -INFINITY;
      for (Eigen::Index i = 0; i < X.cols(); ++i) {
        const double r2 = (X(0, i) - cx) * (X(0, i) - cx) + (X(1, i) - cy) * (X(1, i) - cy);
        if (r2 < R * R) lower = std::max(lower, X(2, i) + std::sqrt(R * R - r2));
      }
      EXPECT_LE(z, upper + 1e-15) << R << ", " << s;
      EXPECT_GE(z, lower - 1e-15) << R << ", " << s;
      EXPECT_LT(upper - z, 2 * sag) << R << ", " << s;
    }
  }
}

// The model carries the surface: a lattice's box faces (the hex FEM's too), a mesh's
// boundary faces, none for node lists; the touch height on a flat top is Z_top + R.
TEST(ModelSurface, LatticeMeshAndNodeList) {
  const Model grid = build_model(parse_scene(
      R"({"body": {"box": {"min": [0, 0, 0], "max": [2, 1, 1]}, "distribution": {"type": "grid", "per_edge": 5}},
          "indenter": {"radius": 0.3}})",
      "inline", kData));
  EXPECT_EQ(grid.surface_triangles.cols(), 6 * 2 * 16);
  expect_closed(grid.surface_triangles, grid.particle_count);
  EXPECT_NEAR(sums(grid.rest_position, grid.surface_triangles).volume, 2.0, 1e-12);
  EXPECT_NEAR(grid.touch_height, 1.0 + 0.3, 1e-15);
  const Model fem = build_model(parse_scene(
      R"({"model": "hex_fem", "body": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}, "distribution": {"type": "grid", "per_edge": 4}},
          "indenter": {"radius": 0.3}})",
      "inline", kData));
  EXPECT_EQ(fem.surface_triangles.cols(), 6 * 2 * 9);
  expect_closed(fem.surface_triangles, fem.particle_count);
  const Model mesh = build_model(parse_scene(
      R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}, "distribution": {"type": "mesh", "file": "cube_tet_small.msh"}},
          "mls": {"volumes": "mesh", "neighbors": 20, "support_rule": "kth_distance", "support_factor": 1.1},
          "indenter": {"radius": 0.3}})",
      "inline", kData));
  const TetMesh tets = read_mesh(kData / "cube_tet_small.msh");
  EXPECT_EQ(mesh.surface_triangles.cols(), static_cast<Eigen::Index>(tets.boundary_faces.size()));
  expect_closed(mesh.surface_triangles, mesh.particle_count);
  EXPECT_NEAR(sums(mesh.rest_position, mesh.surface_triangles).volume, 1.0, 1e-12);
  EXPECT_NEAR(mesh.touch_height, 1.0 + 0.3, 1e-15);
}

// An MLS body of any shape: the dome mesh without a box, its base ("bottom": the lowest
// nodes of its bounding box, the physical surface "base") fixed. The touch height at the pole
// (the tool placed just above it) is pole + R; the surface is the mesh's closed boundary; a short
// press stays healthy.
TEST(ModelSurface, DomeWithoutABox) {
  const Scene scene = parse_scene(
      R"({"body": {"distribution": {"type": "mesh", "file": "dome.msh"}},
          "mls": {"volumes": "mesh", "neighbors": 20, "support_rule": "kth_distance", "support_factor": 1.1},
          "material": {"young_modulus": 5000, "poisson_ratio": 0.3, "density": 1000},
          "fixed": ["bottom"],
          "indenter": {"radius": 0.01, "mass": 0.01, "force": 0.02, "position": [0, 0, 0.0601]},
          "integrator": {"type": "implicit_euler", "dt": 0.001, "damping": 20}})",
      "inline", kData);
  ASSERT_FALSE(scene.box_given);
  const Model m = build_model(scene);
  const fs::path file = kData / "dome.msh";
  const TetMesh mesh = read_mesh(file);
  EXPECT_EQ(m.fixed_count, static_cast<int>(surface_group_nodes(mesh, file, "base").size()));
  EXPECT_NEAR(m.box_volume, mesh.total_volume, 1e-15);
  int pole = 0;
  for (int i = 0; i < m.particle_count; ++i)
    if (m.rest_position(2, i) > m.rest_position(2, pole)) pole = i;
  ASSERT_NEAR(m.rest_position(0, pole), 0.0, 1e-12);
  EXPECT_NEAR(m.touch_height, m.rest_position(2, pole) + 0.01, 1e-15);
  EXPECT_EQ(m.surface_triangles.cols(), static_cast<Eigen::Index>(mesh.boundary_faces.size()));
  expect_closed(m.surface_triangles, m.particle_count);
  const Options opt = options_of(scene);
  State state = make_state(m, opt);
  for (int k = 0; k < 300; ++k) {
    const StepStatus status = step(m, opt, state);
    ASSERT_FALSE(is_fault(status)) << to_string(status) << " at step " << k;
  }
  EXPECT_TRUE(state.position.allFinite());
  const double depth = m.touch_height - state.indenter_center[2];
  EXPECT_GT(depth, 0.0);           // it presses in
  EXPECT_LT(depth, 0.2 * 0.01);    // a small force: a shallow dent (Hertz: about 1.5e-3 m)
}

}  // namespace
}  // namespace palpate
