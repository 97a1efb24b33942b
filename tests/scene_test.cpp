// Scene files: defaults, the shipped scene, every kind of error (field pointer and
// reason), overrides and fixed faces.
#include "core/scene.h"
#include "test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#ifndef PALPATE_SOURCE_DIR
#error "PALPATE_SOURCE_DIR must be defined as the repository root path"
#endif

namespace palpate {
namespace {

namespace fs = std::filesystem;

Scene parse(const std::string& text, const SceneOverrides& overrides = {}) {
  return parse_scene(text, "test.json", fs::temp_directory_path(), overrides);
}

// The SceneError that parsing `text` throws; fails the test if none is thrown.
SceneError error_of(const std::string& text, const SceneOverrides& overrides = {}) {
  try {
    parse(text, overrides);
  } catch (const SceneError& e) {
    return e;
  }
  ADD_FAILURE() << "no SceneError for " << text;
  return SceneError("", "", "");
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// A file in a fresh temporary folder, removed with the fixture.
class TempDir : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("palpate_scene_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p;
  }
  fs::path dir_;
};

// --- defaults and the shipped scene ------------------------------------------

TEST(Scene, EmptyObjectGivesAllDefaults) {
  const Scene s = parse_scene("{}", "some/dir/my_scene.json", "some/dir");
  const Scene d;
  EXPECT_EQ(s.name, "my_scene");  // the source's stem
  EXPECT_EQ(s.source, "some/dir/my_scene.json");
  EXPECT_EQ(s.model, SolidKind::mls);
  EXPECT_EQ(s.box.min, d.box.min);
  EXPECT_EQ(s.box.max, d.box.max);
  EXPECT_EQ(s.distribution.type, DistributionType::grid);
  EXPECT_EQ(s.distribution.per_edge, 18);
  EXPECT_EQ(s.distribution.spacing, 0.0);
  EXPECT_EQ(s.distribution.jitter, d.distribution.jitter);
  EXPECT_EQ(s.distribution.seed, d.distribution.seed);
  EXPECT_TRUE(s.distribution.node_file.empty());
  EXPECT_EQ(s.mls.neighbors, 16);
  EXPECT_EQ(s.mls.support_factor, d.mls.support_factor);
  EXPECT_EQ(s.mls.volumes, VolumeRule::kernel);
  EXPECT_EQ(s.mls.hourglass, d.mls.hourglass);
  EXPECT_EQ(s.mls.regularization, d.mls.regularization);
  EXPECT_EQ(s.material.young_modulus, d.material.young_modulus);
  EXPECT_EQ(s.material.poisson_ratio, d.material.poisson_ratio);
  EXPECT_EQ(s.material.density, d.material.density);
  EXPECT_EQ(s.material.volume_stiffness, d.material.volume_stiffness);
  EXPECT_EQ(s.fixed_faces, face_bottom | faces_sides);
  EXPECT_FALSE(s.indenter.position_given);
  EXPECT_EQ(s.indenter.radius, d.indenter.radius);
  EXPECT_EQ(s.indenter.mass, d.indenter.mass);
  EXPECT_EQ(s.indenter.force, d.indenter.force);
  EXPECT_EQ(s.contact.tolerance, d.contact.tolerance);
  EXPECT_EQ(s.contact.max_iterations, d.contact.max_iterations);
  EXPECT_EQ(s.integrator.type, IntegratorType::rk4);
  EXPECT_EQ(s.integrator.dt, d.integrator.dt);
  EXPECT_EQ(s.integrator.damping, d.integrator.damping);
  EXPECT_EQ(s.integrator.cg_tolerance, d.integrator.cg_tolerance);
  EXPECT_EQ(s.integrator.cg_max_iterations, d.integrator.cg_max_iterations);
  EXPECT_EQ(s.gravity, Vec3::Zero());
  // Derived from R = 0.5 m: the paper's sweep d = 0.01 ... 0.1 m and the former absolute values.
  ASSERT_EQ(s.verify.forces.size(), 10u);
  EXPECT_NEAR(s.verify.forces.front(), 10.36, 0.01);
  EXPECT_NEAR(s.verify.forces.back(), 327.6, 0.1);
  EXPECT_DOUBLE_EQ(s.verify.rest.velocity_tolerance, 1e-4);
  EXPECT_DOUBLE_EQ(s.contact.tolerance, 1e-6);
  EXPECT_EQ(s.verify.rest.force_tolerance, d.verify.rest.force_tolerance);
  EXPECT_EQ(s.verify.rest.window, d.verify.rest.window);
  EXPECT_EQ(s.verify.rest.max_time, d.verify.rest.max_time);
}

// The defaults that scale with the scene follow the indenter radius (and the rest window);
// a value the scene writes is kept, and 0 / [] asks for the derived one.
TEST(Scene, ScaleDefaultsFollowTheIndenterRadius) {
  const Scene s = parse_scene(R"({"indenter": {"radius": 0.01}, "material": {"young_modulus": 2e4},
                                  "verify": {"rest": {"window": 0.1}}})", "hand", ".");
  EXPECT_DOUBLE_EQ(s.contact.tolerance, 2e-8);
  EXPECT_DOUBLE_EQ(s.verify.rest.velocity_tolerance, 1e-5 * 0.01 / 0.1);
  ASSERT_EQ(s.verify.forces.size(), 10u);
  const double E_star = 2e4 / (1 - 0.3 * 0.3);
  // Hertz (docs/physics.md (3.2)) inverted: the sweep is d/R = 0.02 ... 0.2.
  const auto depth_over_R = [&](double F) { return std::pow(3 * F / (4 * E_star * std::sqrt(0.01)), 2.0 / 3.0) / 0.01; };
  EXPECT_NEAR(depth_over_R(s.verify.forces.front()), 0.02, 1e-12);
  EXPECT_NEAR(depth_over_R(s.verify.forces.back()), 0.2, 1e-12);
  const Scene given = parse_scene(R"({"indenter": {"radius": 0.01}, "contact": {"tolerance": 1e-5},
                                      "verify": {"forces": [0.1], "rest": {"velocity_tolerance": 3e-3}}})", "hand", ".");
  EXPECT_EQ(given.contact.tolerance, 1e-5);
  EXPECT_EQ(given.verify.rest.velocity_tolerance, 3e-3);
  EXPECT_EQ(given.verify.forces, std::vector<double>{0.1});
  const Scene zeros = parse_scene(R"({"indenter": {"radius": 0.01}, "material": {"young_modulus": 2e4}, "contact": {"tolerance": 0},
                                      "verify": {"forces": [], "rest": {"velocity_tolerance": 0}}})", "hand", ".");
  EXPECT_DOUBLE_EQ(zeros.contact.tolerance, 2e-8);
  EXPECT_EQ(zeros.verify.forces, s.verify.forces);
}

TEST(Scene, ShippedHertzCube) {
  const fs::path file = fs::path(PALPATE_SOURCE_DIR) / "scenes" / "hertz_cube.json";
  const Scene s = load_scene(file);
  EXPECT_EQ(s.name, "hertz_cube");
  EXPECT_EQ(s.source, file.string());
  EXPECT_EQ(s.model, SolidKind::mls);
  EXPECT_EQ(s.box.min, Vec3(-1, -1, -2));
  EXPECT_EQ(s.box.max, Vec3(1, 1, 0));
  EXPECT_EQ(s.distribution.type, DistributionType::grid);
  EXPECT_EQ(s.distribution.per_edge, 18);
  EXPECT_EQ(s.mls.neighbors, 16);
  EXPECT_EQ(s.mls.support_factor, 1.0);
  EXPECT_EQ(s.mls.volumes, VolumeRule::kernel);
  EXPECT_EQ(s.material.young_modulus, 1e4);
  EXPECT_EQ(s.material.poisson_ratio, 0.3);
  EXPECT_EQ(s.material.density, 1000.0);
  EXPECT_EQ(s.material.volume_stiffness, 0.0);
  EXPECT_EQ(s.fixed_faces, face_bottom | faces_sides);
  EXPECT_EQ(s.indenter.radius, 0.5);
  EXPECT_EQ(s.indenter.mass, 1.0);
  EXPECT_FALSE(s.indenter.position_given);
  EXPECT_EQ(s.indenter.force, 0.0);
  EXPECT_EQ(s.integrator.type, IntegratorType::rk4);
  EXPECT_EQ(s.integrator.dt, 0.001);
  EXPECT_EQ(s.integrator.damping, 10.0);
  EXPECT_EQ(s.gravity, Vec3::Zero());

  // Hertz loads for depths 0.01 ... 0.1 m, to 4 significant digits.
  ASSERT_EQ(s.verify.forces.size(), 10u);
  const double E_star = s.material.young_modulus / (1.0 - s.material.poisson_ratio * s.material.poisson_ratio);
  for (int k = 0; k < 10; ++k) {
    const double d = 0.01 * (k + 1);
    const double F = 4.0 / 3.0 * E_star * std::sqrt(s.indenter.radius) * std::pow(d, 1.5);
    EXPECT_NEAR(s.verify.forces[k], F, 5e-4 * F) << "depth " << d;
  }
}

TEST(Scene, EveryDocumentedFieldIsAccepted) {
  const Scene s = parse(R"({
    "name": "full",
    "model": "mls",
    "body": {
      "box": {"min": [-1,-1,-2], "max": [1,1,0]},
      "distribution": {"type": "jittered_grid", "per_edge": 12, "spacing": 0.25, "jitter": 0.2, "seed": 7,
                       "first_spacing": 0.05, "focus": [0.5, 0, 0], "node_file": "nodes.txt", "file": "cube.msh"}
    },
    "mls": {"neighbors": 26, "max_neighbors": 40, "support_factor": 1.5, "support_rule": "kth_distance",
            "integration": "consistent", "volumes": "lattice", "hourglass": 0.5, "regularization": 1e-4},
    "hex_fem": {"formulation": "corotational", "volumetric_integration": "reduced"},
    "material": {"young_modulus": 2e4, "poisson_ratio": 0.45, "density": 1100, "volume_stiffness": 100,
                 "law": "corotational"},
    "fixed": ["bottom"],
    "indenter": {"radius": 0.25, "mass": 2.0, "position": [0.1, 0.2, 0.5], "force": 30},
    "contact": {"tolerance": 1e-5, "max_iterations": 50},
    "integrator": {"type": "implicit_euler", "dt": 0.01, "damping": 1.0, "cg_tolerance": 1e-6,
                   "cg_max_iterations": 500, "allow_unstable_dt": true},
    "gravity": [0, 0, -9.81],
    "verify": {"forces": [10, 50], "rest": {"velocity_tolerance": 1e-3, "force_tolerance": 1e-2, "window": 0.1,
                                            "max_time": 30}},
    "health": {"enabled": false, "energy_factor": 4, "max_indenter_speed": 2, "max_penetration": 0.01,
               "inversion_sweep_ticks": 8}
  })");
  EXPECT_EQ(s.name, "full");
  EXPECT_EQ(s.distribution.type, DistributionType::jittered_grid);
  EXPECT_EQ(s.distribution.per_edge, 12);
  EXPECT_EQ(s.distribution.spacing, 0.25);
  EXPECT_EQ(s.distribution.jitter, 0.2);
  EXPECT_EQ(s.distribution.seed, 7u);
  EXPECT_EQ(s.distribution.first_spacing, 0.05);
  EXPECT_TRUE(s.distribution.focus_given);
  EXPECT_EQ(s.distribution.focus, Vec3(0.5, 0, 0));
  EXPECT_EQ(s.distribution.node_file.filename(), "nodes.txt");  // kept (resolved), unused by a grid
  EXPECT_EQ(s.distribution.mesh_file.filename(), "cube.msh");   // likewise
  EXPECT_EQ(s.mls.neighbors, 26);
  EXPECT_EQ(s.mls.max_neighbors, 40);
  EXPECT_EQ(s.mls.support_factor, 1.5);
  EXPECT_EQ(s.mls.support_rule, SupportRule::kth_distance);
  EXPECT_EQ(s.mls.integration, IntegrationRule::consistent);
  EXPECT_EQ(s.mls.volumes, VolumeRule::lattice);
  EXPECT_EQ(s.mls.hourglass, 0.5);
  EXPECT_EQ(s.mls.regularization, 1e-4);
  EXPECT_EQ(s.hex_fem.formulation, HexFormulation::corotational);
  EXPECT_EQ(s.hex_fem.volumetric_integration, HexVolumetricIntegration::reduced);
  EXPECT_EQ(s.material.young_modulus, 2e4);
  EXPECT_EQ(s.material.poisson_ratio, 0.45);
  EXPECT_EQ(s.material.density, 1100.0);
  EXPECT_EQ(s.material.volume_stiffness, 100.0);
  EXPECT_EQ(s.material.law, MaterialLaw::corotational);
  EXPECT_EQ(s.fixed_faces, face_bottom);
  EXPECT_TRUE(s.indenter.position_given);
  EXPECT_EQ(s.indenter.position, Vec3(0.1, 0.2, 0.5));
  EXPECT_EQ(s.indenter.radius, 0.25);
  EXPECT_EQ(s.indenter.mass, 2.0);
  EXPECT_EQ(s.indenter.force, 30.0);
  EXPECT_EQ(s.contact.tolerance, 1e-5);
  EXPECT_EQ(s.contact.max_iterations, 50);
  EXPECT_EQ(s.integrator.type, IntegratorType::implicit_euler);
  EXPECT_EQ(s.integrator.dt, 0.01);
  EXPECT_EQ(s.integrator.damping, 1.0);
  EXPECT_EQ(s.integrator.cg_tolerance, 1e-6);
  EXPECT_EQ(s.integrator.cg_max_iterations, 500);
  EXPECT_TRUE(s.integrator.allow_unstable_dt);
  EXPECT_EQ(s.gravity, Vec3(0, 0, -9.81));
  EXPECT_EQ(s.verify.forces, (std::vector<double>{10, 50}));
  EXPECT_EQ(s.verify.rest.velocity_tolerance, 1e-3);
  EXPECT_EQ(s.verify.rest.force_tolerance, 1e-2);
  EXPECT_EQ(s.verify.rest.window, 0.1);
  EXPECT_EQ(s.verify.rest.max_time, 30.0);
  EXPECT_FALSE(s.health.enabled);
  EXPECT_EQ(s.health.energy_factor, 4.0);
  EXPECT_EQ(s.health.max_indenter_speed, 2.0);
  EXPECT_EQ(s.health.max_penetration, 0.01);
  EXPECT_EQ(s.health.inversion_sweep_ticks, 8);
}

TEST(Scene, IntegralFloatsAreIntegers) {
  const Scene s = parse(R"({"body": {"distribution": {"per_edge": 12.0, "seed": 3e2}}})");
  EXPECT_EQ(s.distribution.per_edge, 12);
  EXPECT_EQ(s.distribution.seed, 300u);
}

TEST(Scene, LargeSeedIsExact) {
  const Scene s = parse(R"({"body": {"distribution": {"seed": 18446744073709551615}}})");
  EXPECT_EQ(s.distribution.seed, 18446744073709551615ull);
}

TEST(Scene, ToString) {
  EXPECT_STREQ(to_string(IntegratorType::rk4), "rk4");
  EXPECT_STREQ(to_string(IntegratorType::symplectic_euler), "symplectic_euler");
  EXPECT_STREQ(to_string(IntegratorType::implicit_euler), "implicit_euler");
  EXPECT_STREQ(to_string(DistributionType::grid), "grid");
  EXPECT_STREQ(to_string(DistributionType::jittered_grid), "jittered_grid");
  EXPECT_STREQ(to_string(DistributionType::node_file), "node_file");
  EXPECT_STREQ(to_string(SupportRule::kth_distance), "kth_distance");
  EXPECT_STREQ(to_string(IntegrationRule::consistent), "consistent");
  EXPECT_STREQ(to_string(VolumeRule::lattice), "lattice");
  EXPECT_STREQ(to_string(HexVolumetricIntegration::reduced), "reduced");
  // The names read back.
  for (auto t : {IntegratorType::rk4, IntegratorType::symplectic_euler, IntegratorType::implicit_euler})
    EXPECT_EQ(parse(std::string(R"({"integrator": {"type": ")") + to_string(t) + "\"}}").integrator.type, t);
}

// --- errors -------------------------------------------------------------------

TEST(SceneErrors, WhatNamesSourceFieldAndReason) {
  const SceneError e = error_of(R"({"material": {"poisson_ratio": 0.7}})");
  EXPECT_EQ(e.source(), "test.json");
  EXPECT_EQ(e.field(), "/material/poisson_ratio");
  EXPECT_EQ(e.reason(), "must be a number in (-1, 0.5), got 0.7");
  EXPECT_STREQ(e.what(), "test.json: /material/poisson_ratio: must be a number in (-1, 0.5), got 0.7");
}

TEST(SceneErrors, UnknownTopLevelField) {
  const SceneError e = error_of(R"({"materials": {}})");
  EXPECT_EQ(e.field(), "/materials");
  EXPECT_EQ(e.reason(),
            "unknown field (known: name, model, body, mls, hex_fem, material, fixed, indenter, contact, integrator, gravity, "
            "verify, health)");
}

TEST(SceneErrors, UnknownNestedField) {
  const SceneError e = error_of(R"({"material": {"youngs_modulus": 5000}})");
  EXPECT_EQ(e.field(), "/material/youngs_modulus");
  EXPECT_EQ(e.reason(), "unknown field (known: young_modulus, poisson_ratio, density, volume_stiffness, law, inclusions)");

  const SceneError deep = error_of(R"({"verify": {"rest": {"timeout": 5}}})");
  EXPECT_EQ(deep.field(), "/verify/rest/timeout");
  EXPECT_TRUE(contains(deep.reason(), "known: velocity_tolerance, force_tolerance, window, max_time"));
}

TEST(SceneErrors, UnknownKeyWithPointerCharactersIsEscaped) {
  EXPECT_EQ(error_of(R"({"mls": {"a/b~c": 1}})").field(), "/mls/a~1b~0c");
}

TEST(SceneErrors, WrongType) {
  SceneError e = error_of(R"({"material": {"density": "1000"}})");
  EXPECT_EQ(e.field(), "/material/density");
  EXPECT_TRUE(contains(e.reason(), "expected a number, got string")) << e.reason();

  e = error_of(R"({"integrator": {"type": 4}})");
  EXPECT_EQ(e.field(), "/integrator/type");
  EXPECT_EQ(e.reason(), "expected a string, got number 4");

  e = error_of(R"({"mls": [16]})");
  EXPECT_EQ(e.field(), "/mls");
  EXPECT_EQ(e.reason(), "expected an object, got array of 1 element");

  e = error_of(R"({"fixed": "bottom"})");
  EXPECT_EQ(e.field(), "/fixed");
  EXPECT_TRUE(contains(e.reason(), "expected an array of face names and fixed regions, got string")) << e.reason();

  e = error_of(R"({"contact": {"max_iterations": true}})");
  EXPECT_EQ(e.field(), "/contact/max_iterations");
  EXPECT_EQ(e.reason(), "expected a number, got boolean true");

  e = error_of(R"({"indenter": {"radius": null}})");
  EXPECT_EQ(e.field(), "/indenter/radius");
  EXPECT_EQ(e.reason(), "expected a number, got null");
}

TEST(SceneErrors, NanAsStringIsATypeError) {
  const SceneError e = error_of(R"({"material": {"poisson_ratio": "NaN"}})");
  EXPECT_EQ(e.field(), "/material/poisson_ratio");
  EXPECT_EQ(e.reason(), "expected a number, got string \"NaN\"");
}

TEST(SceneErrors, OutOfRange) {
  struct Case {
    const char* json;
    const char* field;
    const char* reason;
  };
  const Case cases[] = {
      {R"({"material": {"poisson_ratio": -1}})", "/material/poisson_ratio", "must be a number in (-1, 0.5), got -1"},
      {R"({"material": {"poisson_ratio": 0.5}})", "/material/poisson_ratio", "must be a number in (-1, 0.5), got 0.5"},
      {R"({"material": {"young_modulus": 0}})", "/material/young_modulus", "must be a number in (0, 1e12], got 0"},
      {R"({"material": {"young_modulus": 2e12}})", "/material/young_modulus",
       "must be a number in (0, 1e12], got 2e12"},
      {R"({"material": {"density": 1e6}})", "/material/density", "must be a number in (0, 1e5], got 1e6"},
      {R"({"material": {"volume_stiffness": -1}})", "/material/volume_stiffness",
       "must be a number in [0, 1e12], got -1"},
      {R"({"body": {"distribution": {"per_edge": 1}}})", "/body/distribution/per_edge",
       "must be an integer in [2, 200], got 1"},
      {R"({"body": {"distribution": {"per_edge": 201}}})", "/body/distribution/per_edge",
       "must be an integer in [2, 200], got 201"},
      {R"({"body": {"distribution": {"spacing": -0.1}}})", "/body/distribution/spacing",
       "must be a number >= 0, got -0.1"},
      {R"({"body": {"distribution": {"jitter": 0.5}}})", "/body/distribution/jitter",
       "must be a number in [0, 0.5), got 0.5"},
      {R"({"body": {"distribution": {"seed": -1}}})", "/body/distribution/seed",
       "must be a non-negative integer, got -1"},
      {R"({"mls": {"neighbors": 3}})", "/mls/neighbors", "must be an integer in [4, 64], got 3"},
      {R"({"mls": {"neighbors": 65}})", "/mls/neighbors", "must be an integer in [4, 64], got 65"},
      {R"({"mls": {"support_factor": 0}})", "/mls/support_factor", "must be a number in (0, 10], got 0"},
      {R"({"mls": {"hourglass": 101}})", "/mls/hourglass", "must be a number in [0, 100], got 101"},
      {R"({"mls": {"regularization": 1}})", "/mls/regularization", "must be a number in [0, 1), got 1"},
      {R"({"indenter": {"radius": 0}})", "/indenter/radius", "must be a number in (0, 1000], got 0"},
      {R"({"indenter": {"mass": 2e6}})", "/indenter/mass", "must be a number in (0, 1e6], got 2e6"},
      {R"({"indenter": {"force": -2e9}})", "/indenter/force", "must be a number in [-1e9, 1e9], got -2e9"},
      {R"({"contact": {"tolerance": 2}})", "/contact/tolerance", "must be a number in [0, 1], got 2"},
      {R"({"contact": {"max_iterations": 0}})", "/contact/max_iterations",
       "must be an integer in [1, 1000000], got 0"},
      {R"({"integrator": {"dt": 0}})", "/integrator/dt", "must be a number in (0, 1], got 0"},
      {R"({"integrator": {"dt": 1.5}})", "/integrator/dt", "must be a number in (0, 1], got 1.5"},
      {R"({"integrator": {"damping": -1}})", "/integrator/damping", "must be a number in [0, 1e6], got -1"},
      {R"({"integrator": {"cg_tolerance": 1}})", "/integrator/cg_tolerance", "must be a number in (0, 1), got 1"},
      {R"({"integrator": {"cg_max_iterations": 1e7}})", "/integrator/cg_max_iterations",
       "must be an integer in [1, 1000000], got 1e7"},
      {R"({"gravity": [0, 0, -2000]})", "/gravity", "norm must be at most 1000 m/s^2, got 2000"},
      {R"({"verify": {"forces": [10, 0]}})", "/verify/forces/1", "must be a number in (0, 1e9], got 0"},
      {R"({"verify": {"rest": {"window": 0}}})", "/verify/rest/window", "must be a number > 0, got 0"},
      {R"({"verify": {"rest": {"max_time": 1e7}}})", "/verify/rest/max_time", "must be a number in (0, 1e6], got 1e7"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.json);
    const SceneError e = error_of(c.json);
    EXPECT_EQ(e.field(), c.field);
    EXPECT_EQ(e.reason(), c.reason);
  }
}

TEST(SceneErrors, NonIntegerInteger) {
  const SceneError e = error_of(R"({"body": {"distribution": {"per_edge": 3.5}}})");
  EXPECT_EQ(e.field(), "/body/distribution/per_edge");
  EXPECT_EQ(e.reason(), "must be an integer in [2, 200], got 3.5");
  EXPECT_EQ(error_of(R"({"body": {"distribution": {"seed": 1.5}}})").field(), "/body/distribution/seed");
}

TEST(SceneErrors, BadEnums) {
  SceneError e = error_of(R"({"integrator": {"type": "euler"}})");
  EXPECT_EQ(e.field(), "/integrator/type");
  EXPECT_EQ(e.reason(), "unknown integrator 'euler' (known: rk4, symplectic_euler, implicit_euler)");

  e = error_of(R"({"body": {"distribution": {"type": "random"}}})");
  EXPECT_EQ(e.field(), "/body/distribution/type");
  EXPECT_EQ(e.reason(), "unknown distribution type 'random' (known: grid, jittered_grid, graded_grid, node_file, mesh)");

  e = error_of(R"({"mls": {"volumes": "voronoi"}})");
  EXPECT_EQ(e.field(), "/mls/volumes");
  EXPECT_EQ(e.reason(), "unknown volume rule 'voronoi' (known: kernel, lattice, mesh)");

  e = error_of(R"({"model": "fem"})");
  EXPECT_EQ(e.field(), "/model");
  EXPECT_EQ(e.reason(), "unknown model 'fem' (known: mls, hex_fem)");
}

TEST(SceneErrors, Vectors) {
  SceneError e = error_of(R"({"gravity": [0, -9.81]})");
  EXPECT_EQ(e.field(), "/gravity");
  EXPECT_EQ(e.reason(), "expected an array of 3 numbers, got array of 2 elements");

  e = error_of(R"({"indenter": {"position": [0, "up", 1]}})");
  EXPECT_EQ(e.field(), "/indenter/position/1");
  EXPECT_EQ(e.reason(), "expected a number, got string \"up\"");
  EXPECT_EQ(error_of(R"({"gravity": [0, "a", "b"]})").field(), "/gravity/1");  // the first bad element

  e = error_of(R"({"body": {"box": {"min": {"x": 0}}}})");
  EXPECT_EQ(e.field(), "/body/box/min");
  EXPECT_EQ(e.reason(), "expected an array of 3 numbers, got object");
}

TEST(SceneErrors, BoxGeometry) {
  SceneError e = error_of(R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 0]}}})");
  EXPECT_EQ(e.field(), "/body/box");
  EXPECT_EQ(e.reason(), "max must exceed min in every component (z: max 0 <= min 0)");

  e = error_of(R"({"body": {"box": {"min": [-1, -1, -2], "max": [1500, 1, 0]}}})");
  EXPECT_EQ(e.field(), "/body/box");
  EXPECT_EQ(e.reason(), "every edge must be at most 1000 m (x: 1501 m)");
}

TEST(SceneErrors, SpacingGivesNodesPerEdgeInRange) {
  // Default box: edges 2 m. 0.01 m -> 201 nodes; 5 m -> round(0.4) + 1 = 1 node.
  SceneError e = error_of(R"({"body": {"distribution": {"spacing": 0.01}}})");
  EXPECT_EQ(e.field(), "/body/distribution/spacing");
  EXPECT_TRUE(contains(e.reason(), "gives 201 nodes along x")) << e.reason();
  EXPECT_TRUE(contains(e.reason(), "must be in [2, 200]")) << e.reason();
  EXPECT_EQ(error_of(R"({"body": {"distribution": {"spacing": 5}}})").field(), "/body/distribution/spacing");
  EXPECT_EQ(parse(R"({"body": {"distribution": {"spacing": 0.1}}})").distribution.spacing, 0.1);
}

TEST(SceneErrors, SyntaxErrorHasLineAndColumn) {
  // The position is that of the last character read: the end of the offending token "mls".
  const SceneError e = error_of("{\n  \"name\": \"x\",\n  \"model\" \"mls\"\n}");
  EXPECT_EQ(e.field(), "");
  EXPECT_TRUE(contains(e.reason(), "line 3, column 15")) << e.reason();
  EXPECT_TRUE(contains(e.reason(), "expected ':'")) << e.reason();
  EXPECT_FALSE(contains(e.what(), "test.json: :")) << e.what();  // no empty field in what()
  EXPECT_TRUE(contains(e.what(), "test.json: invalid JSON at line 3, column 15")) << e.what();

  const SceneError first_line = error_of("{\"a\" 1}");
  EXPECT_TRUE(contains(first_line.reason(), "line 1, column 6")) << first_line.reason();
  EXPECT_TRUE(contains(error_of("").reason(), "invalid JSON at line 1, column 1")) << error_of("").reason();
}

TEST(SceneErrors, NumberOverflowIsReported) {
  const SceneError e = error_of(R"({"material": {"density": 1e400}})");
  EXPECT_EQ(e.field(), "");
  EXPECT_EQ(e.reason(), "invalid JSON at line 1, column 26: number overflow parsing '1e400'");
}

TEST(SceneErrors, TopLevelMustBeAnObject) {
  const SceneError e = error_of("[1, 2]");
  EXPECT_EQ(e.field(), "");
  EXPECT_EQ(e.reason(), "the top-level value must be an object, got array of 2 elements");
}

TEST(SceneErrors, EmptyName) {
  const SceneError e = error_of(R"({"name": ""})");
  EXPECT_EQ(e.field(), "/name");
  EXPECT_EQ(e.reason(), "must be a non-empty string");
}

TEST_F(TempDir, NodeFileResolvedAgainstBaseDir) {
  write("nodes.txt", "0 0 0\n");
  const Scene s = parse_scene(R"({"body": {"distribution": {"type": "node_file", "node_file": "nodes.txt"}}})",
                              "inline", dir_);
  EXPECT_EQ(s.distribution.type, DistributionType::node_file);
  EXPECT_TRUE(s.distribution.node_file.is_absolute());
  EXPECT_TRUE(fs::equivalent(s.distribution.node_file, dir_ / "nodes.txt"));
}

TEST_F(TempDir, MissingNodeFile) {
  try {
    parse_scene(R"({"body": {"distribution": {"type": "node_file", "node_file": "x.txt"}}})", "inline", dir_);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/body/distribution/node_file");
    EXPECT_EQ(e.reason(), "node file 'x.txt' not found (resolved to " + (dir_ / "x.txt").string() + ")");
  }
}

TEST(SceneErrors, NodeFileRequiredForNodeFileType) {
  const SceneError e = error_of(R"({"body": {"distribution": {"type": "node_file"}}})");
  EXPECT_EQ(e.field(), "/body/distribution/node_file");
  EXPECT_TRUE(contains(e.reason(), "required when type is 'node_file'")) << e.reason();
}

TEST_F(TempDir, LatticeVolumesRefusedForNodeFile) {
  write("nodes.txt", "0 0 0\n");
  try {
    parse_scene(R"({"body": {"distribution": {"type": "node_file", "node_file": "nodes.txt"}},
                    "mls": {"volumes": "lattice"}})",
                "inline", dir_);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/mls/volumes");
    EXPECT_TRUE(contains(e.reason(), "needs a lattice")) << e.reason();
    EXPECT_TRUE(contains(e.reason(), "'kernel'")) << e.reason();
  }
}

TEST_F(TempDir, LoadSceneReadsFileAndResolvesAgainstItsFolder) {
  write("nodes.txt", "0 0 0\n");
  const fs::path file =
      write("cloud.json", R"({"body": {"distribution": {"type": "node_file", "node_file": "nodes.txt"}}})");
  const Scene s = load_scene(file);
  EXPECT_EQ(s.name, "cloud");
  EXPECT_EQ(s.source, file.string());
  EXPECT_TRUE(fs::equivalent(s.distribution.node_file, dir_ / "nodes.txt"));
}

TEST_F(TempDir, LoadSceneErrorsNameTheFile) {
  const fs::path missing = dir_ / "missing.json";
  try {
    load_scene(missing);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.source(), missing.string());
    EXPECT_EQ(e.field(), "");
    EXPECT_EQ(e.reason(), "cannot read file: No such file or directory");
  }
  const fs::path bad = write("bad.json", R"({"mls": {"neighbors": 2}})");
  try {
    load_scene(bad);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.source(), bad.string());
    EXPECT_EQ(e.field(), "/mls/neighbors");
  }
}

// --- overrides ----------------------------------------------------------------

TEST(SceneOverrides, NumericStringAndVector) {
  const Scene s = parse(R"({"body": {"distribution": {"per_edge": 18}}})",
                        {{"body.distribution.per_edge", "12"},
                         {"integrator.type", "implicit_euler"},  // bare string
                         {"gravity", "[0, 0, -9.81]"},
                         {"name", "\"quoted\""},
                         {"material.young_modulus", "2e4"}});
  EXPECT_EQ(s.distribution.per_edge, 12);
  EXPECT_EQ(s.integrator.type, IntegratorType::implicit_euler);
  EXPECT_EQ(s.gravity, Vec3(0, 0, -9.81));
  EXPECT_EQ(s.name, "quoted");
  EXPECT_EQ(s.material.young_modulus, 2e4);
}

TEST(SceneOverrides, CreateMissingObjectsAndIndexArrays) {
  const Scene s = parse("{}", {{"verify.rest.window", "0.2"}, {"indenter.position", "[0,0,1]"}});
  EXPECT_EQ(s.verify.rest.window, 0.2);
  EXPECT_TRUE(s.indenter.position_given);
  EXPECT_EQ(s.indenter.position, Vec3(0, 0, 1));

  const Scene t = parse(R"({"gravity": [0, 0, 0]})", {{"gravity.2", "-9.81"}});
  EXPECT_EQ(t.gravity, Vec3(0, 0, -9.81));
}

TEST(SceneOverrides, LaterOverrideWins) {
  EXPECT_EQ(parse("{}", {{"mls.neighbors", "8"}, {"mls.neighbors", "26"}}).mls.neighbors, 26);
}

TEST(SceneOverrides, UnknownKeyIsRejectedNamingTheOverride) {
  const SceneError e = error_of("{}", {{"body.foo", "1"}});
  EXPECT_EQ(e.field(), "/body/foo");
  EXPECT_EQ(e.source(), "test.json (override body.foo=1)");
  EXPECT_TRUE(contains(e.reason(), "unknown field (known: box, distribution)")) << e.reason();

  const SceneError top = error_of("{}", {{"solver.tolerance", "1e-3"}});
  EXPECT_EQ(top.field(), "/solver");
  EXPECT_EQ(top.source(), "test.json (override solver.tolerance=1e-3)");
}

TEST(SceneOverrides, BadValueNamesTheOverride) {
  SceneError e = error_of(R"({"material": {"poisson_ratio": 0.3}})", {{"material.poisson_ratio", "NaN"}});
  EXPECT_EQ(e.field(), "/material/poisson_ratio");
  EXPECT_EQ(e.source(), "test.json (override material.poisson_ratio=NaN)");
  EXPECT_EQ(e.reason(), "expected a number, got string \"NaN\"");
  EXPECT_TRUE(contains(e.what(), "test.json (override material.poisson_ratio=NaN): /material/poisson_ratio: "));

  e = error_of("{}", {{"integrator.type", "euler"}});
  EXPECT_EQ(e.source(), "test.json (override integrator.type=euler)");
  EXPECT_TRUE(contains(e.reason(), "unknown integrator 'euler'")) << e.reason();

  // An error elsewhere in the file does not blame an unrelated override.
  e = error_of(R"({"mls": {"neighbors": 2}})", {{"integrator.dt", "0.002"}});
  EXPECT_EQ(e.source(), "test.json");
}

TEST(SceneOverrides, MalformedKeys) {
  SceneError e = error_of("{}", {{"mls..neighbors", "8"}});
  EXPECT_EQ(e.source(), "test.json (override mls..neighbors=8)");
  EXPECT_TRUE(contains(e.reason(), "dotted field path")) << e.reason();

  e = error_of(R"({"mls": {"neighbors": 16}})", {{"mls.neighbors.k", "8"}});
  EXPECT_EQ(e.field(), "/mls/neighbors");
  EXPECT_EQ(e.source(), "test.json (override mls.neighbors.k=8)");
  EXPECT_TRUE(contains(e.reason(), "cannot set 'k' in number 16")) << e.reason();
}

// --- fixed faces ---------------------------------------------------------------

TEST(SceneFixed, FaceNames) {
  EXPECT_EQ(parse(R"({"fixed": ["bottom", "sides"]})").fixed_faces, face_bottom | faces_sides);
  EXPECT_EQ(parse(R"({"fixed": ["sides"]})").fixed_faces,
            static_cast<uint32_t>(face_x_min | face_x_max | face_y_min | face_y_max));
  EXPECT_EQ(parse(R"({"fixed": ["top"]})").fixed_faces, face_top);
  EXPECT_EQ(parse(R"({"fixed": ["x_min", "y_max"]})").fixed_faces, face_x_min | face_y_max);
  EXPECT_EQ(parse(R"({"fixed": ["x_max", "y_min", "bottom", "x_max"]})").fixed_faces,
            face_x_max | face_y_min | face_bottom);  // repeats are harmless
  EXPECT_EQ(parse(R"({"fixed": []})").fixed_faces, 0u);  // a free body
  EXPECT_EQ(parse("{}").fixed_faces, face_bottom | faces_sides);
}

TEST(SceneFixed, UnknownFaceNamesItsIndex) {
  const SceneError e = error_of(R"({"fixed": ["bottom", "sides", "front"]})");
  EXPECT_EQ(e.field(), "/fixed/2");
  EXPECT_EQ(e.reason(), "unknown face 'front' (known: bottom, top, x_min, x_max, y_min, y_max, sides)");
  EXPECT_EQ(error_of(R"({"fixed": ["bottom", 3]})").field(), "/fixed/1");
}

TEST(SceneFixed, OverrideFixedFaces) {
  EXPECT_EQ(parse("{}", {{"fixed", "[]"}}).fixed_faces, 0u);
  EXPECT_EQ(parse("{}", {{"fixed", R"(["bottom"])"}}).fixed_faces, face_bottom);
}

TEST(SceneGradedGrid, ParsesAndRejectsSpacingsThatDoNotFit) {
  const Scene s = parse_scene(
      R"({"model": "hex_fem", "body": {"distribution": {"type": "graded_grid", "per_edge": 21, "first_spacing": 0.02}}})",
      "t.json", ".");
  EXPECT_EQ(s.distribution.type, DistributionType::graded_grid);
  EXPECT_DOUBLE_EQ(s.distribution.first_spacing, 0.02);
  EXPECT_FALSE(s.distribution.focus_given);
  try {
    parse_scene(R"({"body": {"distribution": {"type": "graded_grid", "first_spacing": 1.5}}})", "t.json", ".");
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/body/distribution/first_spacing");
    EXPECT_NE(e.reason().find("does not fit"), std::string::npos) << e.reason();
  }
  try {
    parse_scene(R"({"body": {"distribution": {"type": "graded_grid", "focus": [0, 0, 3]}}})", "t.json", ".");
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/body/distribution/focus");
  }
  try {
    parse_scene(R"({"body": {"distribution": {"type": "graded_grid", "first_spacing": -1}}})", "t.json", ".");
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/body/distribution/first_spacing");
  }
}

}  // namespace
}  // namespace palpate

namespace palpate {
namespace {

TEST(SceneHexFem, ModelAndFormulationParse) {
  const Scene s = parse_scene(R"({"model": "hex_fem", "hex_fem": {"formulation": "corotational"}})", "t.json", ".");
  EXPECT_EQ(s.model, SolidKind::hex_fem);
  EXPECT_EQ(s.hex_fem.formulation, HexFormulation::corotational);
  EXPECT_EQ(s.hex_fem.volumetric_integration, HexVolumetricIntegration::full);
  EXPECT_EQ(parse_scene(R"({"model": "hex_fem", "hex_fem": {"volumetric_integration": "reduced"}})", "t.json", ".")
                .hex_fem.volumetric_integration,
            HexVolumetricIntegration::reduced);
  const Scene shipped = load_scene(std::string(PALPATE_SOURCE_DIR) + "/scenes/hertz_cube_fem.json");
  EXPECT_EQ(shipped.model, SolidKind::hex_fem);
  EXPECT_EQ(shipped.integrator.type, IntegratorType::implicit_euler);
}

TEST(SceneHexFem, RejectsNonLatticeCloudsAndUnknownFormulations) {
  try {
    parse_scene(R"({"model": "hex_fem", "body": {"distribution": {"type": "jittered_grid"}}})", "t.json", ".");
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/body/distribution/type");
  }
  try {
    parse_scene(R"({"hex_fem": {"formulation": "large"}})", "t.json", ".");
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/hex_fem/formulation");
    EXPECT_NE(e.reason().find("linear, corotational"), std::string::npos) << e.reason();
  }
  try {
    parse_scene(R"({"hex_fem": {"volumetric_integration": "selective"}})", "t.json", ".");
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/hex_fem/volumetric_integration");
    EXPECT_NE(e.reason().find("full, reduced"), std::string::npos) << e.reason();
  }
}

}  // namespace
}  // namespace palpate

namespace palpate {
namespace {

TEST(SceneMaterialLaw, CorotationalIsAnMlsLawAndUnknownLawsAreNamed) {
  const Scene s = test::scene_from_json(R"({"material": {"law": "corotational"}})");
  EXPECT_EQ(s.material.law, MaterialLaw::corotational);
  EXPECT_EQ(test::scene_from_json("{}").material.law, MaterialLaw::stvk);
  EXPECT_EQ(test::scene_from_json(R"({"material": {"law": "linear"}})").material.law, MaterialLaw::linear);
  EXPECT_EQ(test::scene_from_json(R"({"material": {"law": "neo_hookean"}})").material.law, MaterialLaw::neo_hookean);
  EXPECT_STREQ(to_string(MaterialLaw::neo_hookean), "neo_hookean");
  try {
    test::scene_from_json(R"({"material": {"law": "mooney_rivlin"}})");
    FAIL() << "an unknown law was accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/material/law");
    EXPECT_EQ(e.reason(), "unknown material law 'mooney_rivlin' (known: stvk, corotational, linear, neo_hookean)");
  }
  try {
    test::scene_from_json(R"({"model": "hex_fem", "material": {"law": "neo_hookean"}})");
    FAIL() << "the hex FEM took the MLS neo-Hookean law";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/material/law");
  }
  try {
    test::scene_from_json(R"({"model": "hex_fem", "material": {"law": "corotational"}})");
    FAIL() << "the hex FEM took an MLS law";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/material/law");
  }
}

}  // namespace
}  // namespace palpate
