// The quasi-static solve (analysis/static_contact.h) and the finite-block reference
// (analysis/reference.h): Signorini conditions and force balance checked with the
// element-by-element force routine (an independent code path from the assembled,
// factorised stiffness), agreement with the dynamic settle, Richardson on a
// synthetic sequence, convergence of the refined FEM, and the reference against
// the finite-layer Hertz solution.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "analysis/rest.h"
#include "core/hertz.h"
#include "core/indentation.h"
#include "analysis/reference.h"
#include "core/solid.h"
#include "core/state.h"
#include "analysis/static_contact.h"
#include "test_util.h"

namespace palpate {
namespace {

std::string fem_scene(int per_edge, const std::string& distribution = "grid", const std::string& integrator = "implicit_euler",
                      double dt = 0.01) {
  return R"({"model": "hex_fem", "hex_fem": {"formulation": "linear"},
             "body": {"distribution": {"type": ")" + distribution + R"(", "per_edge": )" + std::to_string(per_edge) + R"(}},
             "integrator": {"type": ")" + integrator + R"(", "dt": )" + std::to_string(dt) + R"(, "damping": 10}})";
}

TEST(LinearStaticContact, SignoriniConditionsAndForceBalance) {
  const test::Setup setup = test::setup_from_json(fem_scene(11, "graded_grid"));
  const Model& model = setup.model;
  const Options& opt = setup.opt;
  LinearStaticContact solver(model);
  State state = make_state(model, opt);
  for (double F : {5.0, 60.0, 250.0}) {
    const StaticSolution sol = solver.solve(F, &state);
    ASSERT_TRUE(sol.converged) << sol.message;
    // Multipliers >= 0 and summing to the command.
    double sum = 0;
    for (double p : state.contact_normal_force) {
      EXPECT_GE(p, 0.0);
      sum += p;
    }
    EXPECT_NEAR(sum, F, 1e-9 * F);
    EXPECT_NEAR(state.indenter_contact_force[2], F, 1e-9 * F);
    // Gaps (vertical, as the linearised contact measures them) >= 0 on every top node
    // under the sphere, and zero where the multiplier is positive.
    const double R = model.indenter_radius, c = state.indenter_center[2];
    const double top = model.rest_position.row(2).maxCoeff();
    std::vector<double> gap(model.particle_count, INFINITY);
    for (int i = 0; i < model.particle_count; ++i) {
      const double dx = model.rest_position(0, i), dy = model.rest_position(1, i);
      if (model.rest_position(2, i) < top - 1e-12 || dx * dx + dy * dy >= R * R) continue;
      gap[i] = c - std::sqrt(R * R - dx * dx - dy * dy) - state.position(2, i);
      EXPECT_GE(gap[i], -1e-10) << "node " << i << " penetrates at F = " << F;
    }
    for (size_t a = 0; a < state.contact_index.size(); ++a)
      if (state.contact_normal_force[a] > 1e-9 * F) {
        EXPECT_NEAR(gap[state.contact_index[a]], 0.0, 1e-10);
      }
    // Equilibrium with the element-by-element forces: f_int + f_contact = 0 at free nodes,
    // and the fixed nodes carry the command.
    Points f(3, model.particle_count);
    elastic_forces(model, state.position, f);
    for (size_t a = 0; a < state.contact_index.size(); ++a)
      f.col(state.contact_index[a]) += state.contact_force.col(static_cast<Eigen::Index>(a));
    double worst = 0, support = 0;
    for (int i = 0; i < model.particle_count; ++i) {
      if (model.fixed[i]) support += f(2, i);
      else worst = std::max(worst, f.col(i).norm());
    }
    EXPECT_LT(worst, 1e-8 * F) << "free nodes out of balance at F = " << F;
    EXPECT_NEAR(-support, F, 1e-8 * F) << "the supports must carry the command";
    EXPECT_NEAR(sol.indentation, indentation(model, state), 1e-15);
  }
}

TEST(LinearStaticContact, AgreesWithTheDynamicSettle) {
  // The dynamic settle uses the exact sphere (radial normals, deformed configuration);
  // the static solve linearises the gap vertically. They differ at O((a/R)^2): below
  // 0.5 % at these depths (a/R < 0.25).
  const test::Setup setup = test::setup_from_json(fem_scene(9));
  const Model& model = setup.model;
  const Options& opt = setup.opt;
  LinearStaticContact solver(model);
  State dynamic = make_state(model, opt);
  for (double F : {20.0, 80.0}) {
    const StaticSolution sol = solver.solve(F);
    ASSERT_TRUE(sol.converged);
    const PressResult press = press_to_rest(model, opt, setup.scene.verify.rest, dynamic, F);
    ASSERT_TRUE(press.at_rest);
    EXPECT_NEAR(press.indentation, sol.indentation, 5e-3 * sol.indentation) << "F = " << F;
  }
}

TEST(RelaxToRest, AgreesWithTheDynamicSettleForTheMeshlessSolid) {
  const std::string scene = R"({"body": {"distribution": {"per_edge": 8}},
                                "integrator": {"type": "symplectic_euler", "dt": 0.001, "damping": 10}})";
  const test::Setup setup = test::setup_from_json(scene);
  const Model& model = setup.model;
  const Options& opt = setup.opt;
  State relaxed = make_state(model, opt), dynamic = make_state(model, opt);
  const StaticSolution sol = relax_to_rest(model, opt, setup.scene.verify.rest, relaxed, 60.0);
  ASSERT_TRUE(sol.converged) << sol.message;
  const PressResult press = press_to_rest(model, opt, setup.scene.verify.rest, dynamic, 60.0);
  ASSERT_TRUE(press.at_rest);
  // Both stop when the rest criteria hold (force balance 1e-3, motion 1e-4 m/s).
  EXPECT_NEAR(sol.indentation, press.indentation, 2e-3 * press.indentation);
}

TEST(Richardson, RecoversOrderAndLimitOfASyntheticSequence) {
  const double h[3] = {1.0 / 16, 1.0 / 24, 1.0 / 40};
  double d[3];
  for (int k = 0; k < 3; ++k) d[k] = 0.05 + 0.3 * std::pow(h[k], 1.5);
  double limit, order;
  ASSERT_TRUE(richardson(h, d, limit, order));
  EXPECT_NEAR(order, 1.5, 1e-9);
  EXPECT_NEAR(limit, 0.05, 1e-12);
  const double oscillating[3] = {0.05, 0.051, 0.0505};
  EXPECT_FALSE(richardson(h, oscillating, limit, order));
}

// The graded FEM converges toward its refined reference: the sweep's L2 error falls
// level by level (about 20 s), and the reference lies in the band the finite-layer
// Hertz solution allows (docs/physics.md §3): fixed side walls make the block stiffer
// (shallower) than the layer by a few per cent, the sphere against Hertz's paraboloid
// makes it deeper by at most ~1.3 % at d/R = 0.2.
// The reference is a static solve: the scene's integrator and dt play no part, so a
// time step outside the envelope of the fine reference lattices must not refuse it
// (it did: a corotational MLS scene at symplectic Euler 4 ms with E raised).
TEST(FiniteBlockReference, IgnoresTheScenesTimeStepAndLaw) {
  const Scene scene = test::scene_from_json(
      R"({"material": {"young_modulus": 1e7, "law": "corotational"},
          "integrator": {"type": "symplectic_euler", "dt": 0.004}})");
  ReferenceOptions options;
  options.levels = {5, 7, 9};
  const Reference ref = finite_cube_reference(scene, {1e4}, options);
  ASSERT_EQ(ref.indentation.size(), 1u);
  EXPECT_GT(ref.indentation[0], 0.0);
  EXPECT_THROW(build_model(scene), SceneError);  // the scene itself is outside it
}

TEST(FiniteBlockReference, RefinedFemConvergesAndMatchesTheFiniteLayer) {
  const Scene scene = test::scene_from_json("{}");
  const std::vector<double> forces = {10.36, 53.83, 152.3, 327.6};
  ReferenceOptions options;
  // Coarse levels well apart: between close levels the contact ring oscillation
  // (about 0.5 %) can hide the trend.
  options.levels = {7, 9, 11, 13};
  const Reference ref = finite_cube_reference(scene, forces, options);
  options.levels = {21, 25, 29};
  const Reference fine = finite_cube_reference(scene, forces, options);
  auto l2 = [&](const std::vector<double>& d) {
    double num = 0, den = 0;
    for (size_t f = 0; f < forces.size(); ++f) {
      num += std::pow(d[f] - fine.indentation[f], 2);
      den += std::pow(fine.indentation[f], 2);
    }
    return std::sqrt(num / den);
  };
  double previous = INFINITY;
  for (const auto& level : ref.levels) {
    const double e = l2(level.indentation);
    EXPECT_LT(e, previous) << "level " << level.per_edge;
    previous = e;
  }
  EXPECT_LT(previous, 0.01);
  for (size_t f = 0; f < forces.size(); ++f) {
    const double layer = hertz::depth_finite_layer(forces[f], 0.5, 1e4, 0.3, 2.0);
    const double e = (fine.indentation[f] - layer) / layer;
    EXPECT_GT(e, -0.04) << "F = " << forces[f];
    EXPECT_LT(e, 0.013) << "F = " << forces[f];
  }
}

TEST(FiniteBlockReference, StoredReferenceOfTheDefaultSceneHasItsKey) {
  std::ifstream in(std::string(PALPATE_SOURCE_DIR) + "/scenes/references/hertz_cube.json");
  ASSERT_TRUE(in) << "scenes/references/hertz_cube.json is missing (palpate-reference --out)";
  std::stringstream text;
  text << in.rdbuf();
  const Reference ref = reference_from_json(text.str());
  const Scene scene = load_scene(std::string(PALPATE_SOURCE_DIR) + "/scenes/hertz_cube.json");
  EXPECT_EQ(ref.key, reference_key(scene));
  const auto found = find_reference(scene, std::string(PALPATE_SOURCE_DIR) + "/scenes/references");
  ASSERT_TRUE(found.has_value());
  // Interpolation is exact at the stored forces and Hertz-shaped between them.
  EXPECT_DOUBLE_EQ(reference_indentation(*found, found->forces[3]), found->indentation[3]);
  const double mid = reference_indentation(*found, 0.5 * (found->forces[3] + found->forces[4]));
  EXPECT_GT(mid, found->indentation[3]);
  EXPECT_LT(mid, found->indentation[4]);
  EXPECT_TRUE(std::isnan(reference_indentation(*found, 1e6)));
}

}  // namespace
}  // namespace palpate
