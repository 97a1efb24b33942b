// Multirate symplectic Euler: the schedule (core/rate_schedule.h) and the step
// (core/integrators.h; docs/physics.md (1.20), (1.21)).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/checkpoint.h"
#include "core/mls_forces.h"
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/step.h"
#include "tests/test_util.h"

namespace palpate {
namespace {

namespace fs = std::filesystem;

// A small graded cube (the Hertz cube's cloud, 9 per edge), its step at the envelope's half.
Scene graded_cube(int max_interval, const std::string& law = "corotational", double hourglass = 0.0) {
  return load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "hertz_cube_graded.json",
                    {{"body.distribution.per_edge", "9"},
                     {"body.distribution.first_spacing", "0.1"},
                     {"mls.neighbors", "26"},
                     {"mls.hourglass", std::to_string(hourglass)},
                     {"material.law", "\"" + law + "\""},
                     {"integrator.max_interval", std::to_string(max_interval)}});
}

Scene block_follow(int max_interval) {
  return load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_block_follow.json",
                    {{"integrator.max_interval", std::to_string(max_interval)}});
}

// Positions a little off the rest ones (seeded), for forces that are not zero.
Points perturbed(const Model& m, double amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  Points x = m.rest_position;
  for (int i = 0; i < m.particle_count; ++i)
    for (int c = 0; c < 3; ++c) x(c, i) += u(rng);
  return x;
}

int classes_used(const RateSchedule& s) {
  std::vector<int> seen(65, 0);
  for (uint8_t k : s.interval) seen[k] = 1;
  return std::count(seen.begin(), seen.end(), 1);
}

TEST(Subcycling, TheForcesOfAllBlocksListedAreTheForceLoopsBitForBit) {
  // The listed loop takes two blocks at a time for the corotational law, one for the others,
  // with and without hourglass control.
  for (const char* law : {"corotational", "stvk", "neo_hookean"})
    for (double hourglass : {0.0, 0.15}) {
      const Model m = build_model(graded_cube(1, law, hourglass));
      const Points x = perturbed(m, 0.01, 7);
      std::vector<int> all(m.blocks.size());
      for (size_t b = 0; b < all.size(); ++b) all[b] = static_cast<int>(b);
      // On one thread and on two (their own split of the list, the full loop's when all are listed).
      for (int threads : {1, 2}) {
        Points full(3, m.particle_count), listed(3, m.particle_count);
        WorkerThreads pool(threads, m.particle_count);
        mls_internal_forces(m, x, full, pool);
        mls_internal_forces_of_blocks(m, x, all.data(), static_cast<int>(all.size()), listed, pool);
        EXPECT_TRUE(full == listed) << law << ", hourglass " << hourglass << ", threads " << threads;
        EXPECT_GT(full.norm(), 0.0);
      }
    }
}

TEST(Subcycling, OnTwoThreadsItIsTheOneThreadRunToRoundOff) {
  // The tick's listed blocks split over two threads, each scattering into its own buffer: the
  // same forces summed in another order. A press stepped both ways stays within round-off
  // (each step's sums differ in their last bits, and the differences do not grow into a
  // drift over a short run), and the two-thread run repeats itself bit for bit.
  const Scene scene = graded_cube(8);
  const Model m = build_model(scene);
  ASSERT_GE(classes_used(m.rate_schedule), 2);
  Options one = options_of(scene), two = one;
  two.integrator.threads = 2;
  State a = make_state(m, one), b = make_state(m, two), c = make_state(m, two);
  double depth_scale = 0.0;
  for (int t = 0; t < 120; ++t) {
    a.force_command = b.force_command = c.force_command = press_down(150.0);
    ASSERT_FALSE(is_fault(step(m, one, a)));
    ASSERT_FALSE(is_fault(step(m, two, b)));
    ASSERT_FALSE(is_fault(step(m, two, c)));
    depth_scale = std::max(depth_scale, (a.position - m.rest_position).cwiseAbs().maxCoeff());
  }
  ASSERT_FALSE(a.contact_index.empty());
  ASSERT_GT(depth_scale, 0.0);
  EXPECT_FALSE(a.position == b.position);  // the sums' order did change
  EXPECT_LT((a.position - b.position).cwiseAbs().maxCoeff(), 1e-9 * depth_scale);
  EXPECT_LT((a.indenter_center - b.indenter_center).norm(), 1e-9 * depth_scale);
  EXPECT_TRUE(b.position == c.position);
  EXPECT_TRUE(b.velocity == c.velocity);
}

TEST(Subcycling, EveryTickListsEveryDomainThatHoldsAParticleUpdatingAtIt) {
  const Model m = build_model(block_follow(8));
  const RateSchedule& s = m.rate_schedule;
  ASSERT_EQ(s.period, 8);
  EXPECT_GE(classes_used(s), 3);
  // The block whose lane holds each particle's domain (the schedule regroups the blocks).
  std::vector<int> block_of(m.particle_count, -1);
  for (size_t b = 0; b < m.blocks.size(); ++b)
    for (int l = 0; l < m.blocks[b].lanes; ++l) {
      ASSERT_EQ(block_of[m.blocks[b].particle[l]], -1) << "a particle in two lanes";
      block_of[m.blocks[b].particle[l]] = static_cast<int>(b);
    }
  ASSERT_EQ(std::count(block_of.begin(), block_of.end(), -1), 0) << "a particle in no lane";
  // Every interval is a power of two within the period, every phase below its interval.
  for (int i = 0; i < m.particle_count; ++i) {
    const int k = s.interval[i];
    ASSERT_TRUE(k >= 1 && k <= s.period && (k & (k - 1)) == 0);
    ASSERT_LT(s.phase[i], k);
  }
  for (int p = 0; p < s.period; ++p) {
    std::vector<char> listed(m.blocks.size(), 0);
    for (int k = s.block_offset[p]; k < s.block_offset[p + 1]; ++k) listed[s.block_index[k]] = 1;
    std::vector<char> updates(m.particle_count, 0);  // the free particles due at phase p
    for (int i = 0; i < m.particle_count; ++i) updates[i] = !m.fixed[i] && p % s.interval[i] == s.phase[i];
    int missing = 0;
    // Domain of particle c: c and its neighbours; its block must be listed when one updates.
    for (int c = 0; c < m.particle_count; ++c) {
      bool needed = updates[c];
      for (int a = m.neighbor_offset[c]; a < m.neighbor_offset[c + 1]; ++a) needed = needed || updates[m.neighbor_index[a]];
      missing += needed && !listed[block_of[c]];
    }
    EXPECT_EQ(missing, 0) << "phase " << p;
  }
}

TEST(Subcycling, WithEveryIntervalOneItIsSymplecticEulerBitForBit) {
  const Scene scene = graded_cube(8);
  Model multi = build_model(scene);
  build_rate_schedule(multi, 8, scene.integrator.dt, 1e-9);  // every particle every tick, the blocks in particle order
  const Model one = build_model(graded_cube(1));
  const Options o1 = options_of(graded_cube(1)), o8 = options_of(scene);
  State a = make_state(one, o1), b = make_state(multi, o8);
  for (int t = 0; t < 60; ++t) {
    a.force_command = b.force_command = press_down(100.0);
    ASSERT_FALSE(is_fault(step(one, o1, a)));
    ASSERT_FALSE(is_fault(step(multi, o8, b)));
  }
  ASSERT_FALSE(a.contact_index.empty());
  EXPECT_TRUE(a.position == b.position);
  EXPECT_TRUE(a.velocity == b.velocity);
  EXPECT_EQ(a.indenter_center, b.indenter_center);
}

TEST(Subcycling, ACheckpointRestoredRepeatsTheRunBitForBit) {
  // Restored at the tick it was saved at, the run repeats; restored later (a session's clock
  // keeps running), each particle keeps the ticks since its last update.
  const Scene scene = graded_cube(8);
  const Model m = build_model(scene);
  ASSERT_GE(classes_used(m.rate_schedule), 2);
  const Options opt = options_of(scene);
  State s = make_state(m, opt);
  s.force_command = press_down(150.0);
  for (int t = 0; t < 37; ++t) ASSERT_FALSE(is_fault(step(m, opt, s)));
  const Checkpoint saved(s);
  const std::vector<int64_t> since_saved = [&] {
    std::vector<int64_t> since(s.elastic_update_tick);
    for (int64_t& t : since) t = s.tick - t;
    return since;
  }();
  for (int t = 0; t < 21; ++t) ASSERT_FALSE(is_fault(step(m, opt, s)));
  const Points first = s.position;
  saved.restore(s);
  for (size_t i = 0; i < since_saved.size(); ++i) ASSERT_EQ(s.tick - s.elastic_update_tick[i], since_saved[i]);
  s.tick = saved.tick();
  saved.restore(s);
  for (int t = 0; t < 21; ++t) ASSERT_FALSE(is_fault(step(m, opt, s)));
  EXPECT_TRUE(first == s.position);
}

TEST(Subcycling, APressRestsOnTheOneRateEquilibriumWithoutRippleAndTheReleaseDiesAway) {
  // The independent truth is the equilibrium of the same model stepped at one rate (a fixed
  // point of both schemes is the static solution). The contact particles at the edge of the
  // patch are coarse ones: without their update at every tick the tool's force alternated by
  // 0.2 % from tick to tick at rest.
  const Scene one = block_follow(1), multi = block_follow(8);
  const Model m1 = build_model(one), m8 = build_model(multi);
  ASSERT_GE(classes_used(m8.rate_schedule), 3);
  const Options o1 = options_of(one), o8 = options_of(multi);
  State s1 = make_state(m1, o1), s8 = make_state(m8, o8);
  const int press = 1500, release = 600;  // (the sanitized builds leave this case out: tests/CMakeLists.txt)
  double worst_gap = 0, ripple = 0, previous = 0, kinetic_at_release = 0;
  int coarse_contacts = 0;
  for (int t = 0; t < press + release; ++t) {
    const double force = t < press ? 0.262 : 0.0;
    s1.force_command = s8.force_command = press_down(force);
    ASSERT_FALSE(is_fault(step(m1, o1, s1))) << t;
    const StepStatus status = step(m8, o8, s8);
    ASSERT_FALSE(is_fault(status)) << t << ": " << to_string(status);
    worst_gap = std::max(worst_gap, std::abs(s1.indenter_center.z() - s8.indenter_center.z()));
    const double F = s8.indenter_contact_force.z();
    if (t >= press - 100 && t < press) ripple = std::max(ripple, std::abs(F - previous) / F);
    previous = F;
    if (t == press - 1) {
      for (int i : s8.contact_index) coarse_contacts += m8.rate_schedule.interval[i] > 1;
      const double depth_1 = m1.touch_height - s1.indenter_center.z(), depth_8 = m8.touch_height - s8.indenter_center.z();
      EXPECT_NEAR(depth_8, depth_1, 1e-4 * depth_1);
      EXPECT_NEAR(F, s1.indenter_contact_force.z(), 1e-4 * F);
      std::printf("at rest under 0.262 N: depth %.6f mm (one rate %.6f), F %.6f N (%.6f); %d of %zu contacts coarse\n",
                  1e3 * depth_8, 1e3 * depth_1, F, s1.indenter_contact_force.z(), coarse_contacts, s8.contact_index.size());
    }
    if (t == press + 50) kinetic_at_release = s8.out.free_motion_kinetic;
  }
  EXPECT_GE(coarse_contacts, 1) << "the press must reach coarse particles for the ripple check to mean anything";
  EXPECT_LT(ripple, 1e-5) << "the tool's force changes from tick to tick at rest";
  EXPECT_LT(worst_gap, 2e-5) << "m: the press's path against one rate";
  EXPECT_LT(s8.out.free_motion_kinetic, 1e-2 * kinetic_at_release) << "the released tissue's motion dies away";
  std::printf("largest tick-to-tick change of F at rest %.2e of F; tool path within %.2f um of one rate; kinetic "
              "energy %.3e J 50 ticks after the release, %.3e J at the end\n",
              ripple, 1e6 * worst_gap, kinetic_at_release, s8.out.free_motion_kinetic);
}

TEST(Subcycling, BadSettingsAreRefusedByName) {
  auto message = [](const std::vector<std::pair<std::string, std::string>>& overrides) -> std::string {
    try {
      // The small cube: two of the refusals come at the end of the model's build.
      SceneOverrides o = {{"body.distribution.per_edge", "9"}, {"body.distribution.first_spacing", "0.1"}};
      o.insert(o.end(), overrides.begin(), overrides.end());
      (void)build_model(load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "hertz_cube_graded.json", o));
    } catch (const std::exception& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(message({{"integrator.max_interval", "3"}}).find("power of two"), std::string::npos);
  EXPECT_NE(message({{"integrator.max_interval", "128"}}).find("max_interval"), std::string::npos);
  EXPECT_NE(message({{"integrator.max_interval", "4"}, {"integrator.type", "\"rk4\""}}).find("symplectic_euler integrator only"),
            std::string::npos);
  EXPECT_EQ(message({{"integrator.max_interval", "4"}, {"integrator.threads", "2"}}), "");  // two threads: built
  // A step longer than the schedule's, or a schedule the model lacks, is refused by the step.
  const Scene scene = graded_cube(4);
  const Model m = build_model(scene);
  Options opt = options_of(scene);
  State s = make_state(m, opt);
  opt.integrator.dt *= 1.5;
  EXPECT_THROW(step(m, opt, s), std::invalid_argument);
  opt = options_of(scene);
  opt.integrator.max_interval = 8;
  EXPECT_THROW(step(m, opt, s), std::invalid_argument);
  const Model one = build_model(graded_cube(1));
  opt.integrator.max_interval = 4;
  State s1 = make_state(one, opt);
  EXPECT_THROW(step(one, opt, s1), std::invalid_argument);
}

}  // namespace
}  // namespace palpate

