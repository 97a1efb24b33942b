// The spacing a scene asks for (core/resolution.h, docs/physics.md (6.1)-(6.3)), and
// the graded lattice that takes it when the scene gives no first_spacing.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/mesh_reader.h"
#include "core/resolution.h"
#include "core/scene.h"

namespace palpate {
namespace {

Scene scene_of(const std::string& json, const SceneOverrides& overrides = {},
               SceneFiles files = SceneFiles::required) {
  return parse_scene(json, "test.json", PALPATE_SOURCE_DIR "/scenes", overrides, files);
}

// a_min from Hertz written out here: F = 4/3 E* sqrt(R) d^(3/2), a = sqrt(R d).
double hertz_contact_radius(double F, double R, double E, double nu) {
  const double E_star = E / (1 - nu * nu);
  const double d = std::pow(3 * F / (4 * E_star * std::sqrt(R)), 2.0 / 3.0);
  return std::sqrt(R * d);
}

TEST(Resolution, ContactSpacingIsAThirdOfTheSmallestContactRadius) {
  const Scene s = scene_of(R"({"indenter": {"radius": 0.3}, "material": {"young_modulus": 5000, "poisson_ratio": 0.45},
                               "verify": {"forces": [4, 1, 2]}})");
  const Resolution r = required_resolution(s);
  EXPECT_EQ(r.smallest_force, 1.0);
  const double a = hertz_contact_radius(1.0, 0.3, 5000, 0.45);
  EXPECT_NEAR(r.smallest_contact_radius, a, 1e-12 * a);
  EXPECT_NEAR(r.contact_spacing, a / 3, 1e-12 * a);
  EXPECT_NEAR(r.smallest_depth * 0.3, a * a, 1e-12 * a * a);
  EXPECT_EQ(r.finest_spacing(), r.contact_spacing);
}

TEST(Resolution, TheDefaultSweepAsksForTheShippedGradedSpacing) {
  // d/R = 0.02 at the default R = 0.5 m: a = sqrt(0.5 x 0.01) = 0.0707 m, h = 0.0236 m,
  // the 0.025 m the accurate graded scenes were tuned to.
  const Resolution r = required_resolution(scene_of("{}"));
  EXPECT_NEAR(r.smallest_contact_radius, std::sqrt(0.5 * 0.01), 1e-9);
  EXPECT_NEAR(r.contact_spacing, std::sqrt(0.005) / 3, 1e-9);
}

TEST(Resolution, AGradedLatticeWithoutFirstSpacingTakesTheRequiredSpacing) {
  const std::string json = R"({"body": {"distribution": {"type": "graded_grid", "per_edge": 15}},
                               "indenter": {"radius": 0.3}, "verify": {"forces": [1, 5]}})";
  const Scene s = scene_of(json);
  EXPECT_NEAR(s.distribution.first_spacing, hertz_contact_radius(1.0, 0.3, 1e4, 0.3) / 3, 1e-12);
  // Given, it is kept; 0 is "derived" as absent is.
  EXPECT_EQ(scene_of(json, {{"body.distribution.first_spacing", "0.05"}}).distribution.first_spacing, 0.05);
  EXPECT_EQ(scene_of(json, {{"body.distribution.first_spacing", "0"}}).distribution.first_spacing,
            s.distribution.first_spacing);
  // A lattice too coarse for the derived spacing says so at the field.
  try {
    scene_of(json, {{"body.distribution.per_edge", "3"}, {"verify.forces", "[1e-6]"}});
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/body/distribution/first_spacing") << e.what();
  }
}

TEST(Resolution, EveryInclusionIsSpannedBySixSpacings) {
  const Scene s = scene_of(R"({"material": {"inclusions": [
      {"sphere": {"center": [0, 0, -0.5], "radius": 0.25}, "young_modulus": 3e4, "poisson_ratio": 0.3},
      {"box": {"min": [0.2, 0.2, -1], "max": [0.6, 0.3, -0.8]}, "young_modulus": 3e4, "poisson_ratio": 0.3}]}})");
  const Resolution r = required_resolution(s);
  ASSERT_EQ(r.inclusions.size(), 2u);
  EXPECT_EQ(r.inclusions[0].spacing, 0.25 / 6);
  EXPECT_EQ(r.inclusions[0].center, Vec3(0, 0, -0.5));
  EXPECT_NEAR(r.inclusions[1].spacing, 0.05 / 6, 1e-15);  // the smallest half-edge, 0.05 m
  EXPECT_NEAR(r.inclusions[1].radius, 0.5 * std::sqrt(0.16 + 0.01 + 0.04), 1e-15);
  EXPECT_NEAR(r.finest_spacing(), 0.05 / 6, 1e-15);  // finer than the contact's 0.0236 m
}

TEST(Resolution, ASceneWhoseMeshIsStillToBeMadeCanBeReadForItsDescription) {
  const std::string json =
      R"({"body": {"distribution": {"type": "mesh", "file": "meshes/not_made_yet.msh"}}, "mls": {"volumes": "mesh"}})";
  EXPECT_THROW(scene_of(json), SceneError);
  const Scene s = scene_of(json, {}, SceneFiles::not_required);
  EXPECT_EQ(s.distribution.type, DistributionType::mesh);
  EXPECT_GT(required_resolution(s).contact_spacing, 0.0);
}

// A group inclusion (a physical volume of the body's mesh, docs/scene-format.md) is sized from
// its tetrahedra: tests/data/lump_block.msh's "lump" is a ball of radius 1 cm centred at
// (0, 0, -2 cm), meshed conformally (tests/data/lump_block.geo). Without the mesh it is left out.
TEST(Resolution, AGroupInclusionIsSizedFromItsTetrahedra) {
  const std::string json = R"({"body": {"distribution": {"type": "mesh", "file": "lump_block.msh"}},
      "mls": {"volumes": "mesh"}, "indenter": {"radius": 0.01}, "verify": {"forces": [0.05, 0.262]},
      "material": {"young_modulus": 2e4, "poisson_ratio": 0.3, "inclusions": [
        {"sphere": {"center": [0.03, 0, -0.02], "radius": 0.006}, "young_modulus": 6e4, "poisson_ratio": 0.3},
        {"group": "lump", "young_modulus": 8e4, "poisson_ratio": 0.45}]}})";
  const Scene s = parse_scene(json, "test.json", PALPATE_SOURCE_DIR "/tests/data");
  EXPECT_EQ(required_resolution(s).inclusions.size(), 1u);  // the sphere; the group needs the mesh
  const Resolution r = required_resolution(s, read_mesh(s.distribution.mesh_file));
  ASSERT_EQ(r.inclusions.size(), 2u);  // in the scene's order
  EXPECT_TRUE(r.inclusions[0].group.empty());
  EXPECT_EQ(r.inclusions[0].spacing, 0.006 / 6);
  const RegionResolution& lump = r.inclusions[1];
  EXPECT_EQ(lump.group, "lump");
  EXPECT_LT((lump.center - Vec3(0, 0, -0.02)).norm(), 2e-4);  // a polyhedral ball: its centroid
  EXPECT_NEAR(lump.radius, 0.01, 3e-4);                      // the farthest node: on the sphere
  // 3V/A of an inscribed polyhedron is a little below the ball's radius (measured 0.0097 m).
  EXPECT_GT(lump.spacing, 0.95 * 0.01 / 6);
  EXPECT_LT(lump.spacing, 0.01 / 6);
  EXPECT_GT(lump.mesh_spacing, 0.001);  // the mesh's own edge there (the .geo asks for 3 mm)
  EXPECT_LT(lump.mesh_spacing, 0.01);
  EXPECT_EQ(r.finest_spacing(), std::min({r.contact_spacing, 0.001, lump.spacing}));
  // An unknown group is refused with the names the mesh has.
  std::string typo_json = json;
  typo_json.replace(typo_json.find("\"lump\""), 6, "\"lmup\"");
  const Scene typo = parse_scene(typo_json, "test.json", PALPATE_SOURCE_DIR "/tests/data");
  EXPECT_THROW(required_resolution(typo, read_mesh(typo.distribution.mesh_file)), std::runtime_error);
}

}  // namespace
}  // namespace palpate
