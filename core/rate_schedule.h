#pragma once
// Multirate symplectic Euler's schedule (docs/physics.md §1, "Subcycling"): which particles
// take an elastic update at which tick, and which force blocks a tick evaluates.
//
// A graded cloud's coarse particles could step many times longer than its finest ones. A
// particle i of update interval k_i (a power of two) takes its elastic force every k_i ticks,
// at the ticks t = phi_i (mod k_i), as the impulse of a step of k_i dt (v += k_i dt f / m),
// and moves with its velocity at every tick (x += dt v): symplectic Euler of step k_i dt on
// the elastic force, the node-partition subcycling of Belytschko, Yen and Mullen (1979), its
// fine side reading the coarse side's positions as they move along their velocities.
// Contact, damping and gravity act on every particle at every tick. A coarse particle near the
// tool (within its support radius of the sphere) updates at every tick, with the ticks since
// its last update, so that no particle in contact takes its force in bursts.
//
// A tick evaluates the force blocks (Model::blocks) of every support domain holding a particle
// that updates at that tick; the others' forces would be discarded. A state at rest stays at
// rest (every updating particle's force is complete), so statics are those of one rate.
#include <cstdint>
#include <vector>

namespace palpate {

struct Model;

// The fraction of a particle's own stable step its update interval may take (build_rate_schedule):
// on palpation_block_follow's press and release the scheme ran stable at 0.9 and blew up at 1.0.
inline constexpr double kSubcyclingSafety = 0.7;
// A coarse particle within this fraction of its support radius of the tool's sphere updates at
// every tick (a quarter: 0.5 mm or more on the follow scenes, five ticks of a tool at 10 cm/s).
inline constexpr double kSubcyclingReach = 0.25;

struct RateSchedule {
  // Ticks after which every particle's phase repeats: the longest interval (1: one rate, the
  // schedule empty and unused).
  int period = 1;
  double dt = 0.0;  // s, the step it was made for: a longer one would take the coarse particles past their stable step
  std::vector<uint8_t> interval;  // n: k_i, ticks between particle i's elastic updates (power of 2)
  std::vector<uint8_t> phase;     // n: phi_i < k_i; i updates at the ticks t = phi_i (mod k_i)
  // CSR over the period's phases p = t mod period: the blocks a tick of phase p evaluates
  // (ascending). Which particles update at it follows from interval and phase.
  std::vector<int> block_offset, block_index;  // period + 1, sum of blocks
  // The same as bits: bit p of block_ticks[b] set when a tick of phase p evaluates block b.
  std::vector<uint64_t> block_ticks;
  // CSR over the particles: the blocks whose support domains hold particle i (ascending), for
  // the particles near the tool, which update at every tick (integrators.h).
  std::vector<int> particle_block_offset, particle_block_index;  // n + 1, sum
  // Neighbour slots (4 pairs each) a tick of phase p evaluates, and all blocks' (for the
  // benchmark's figures).
  std::vector<int64_t> slots_at_phase;
  int64_t slots_total = 0;
};

// Makes the model's schedule (Model::rate_schedule) of longest interval max_interval (a power
// of two, 1 ... 64) for stepping at dt, and regroups its force blocks (core/force_blocks.h)
// so that support domains evaluated at the same ticks share a block; for an MLS model with
// the blocked layout, its fixed particles and spectral_time_step set (build_model's last
// stage). The interval of particle i is the largest power of two k with k dt <= safety x its
// own stable step (1.20), at most max_interval: the model's stable step (its spectral
// estimate when build_model computed one, else the spacing envelope; core/time_step.h) times
// sqrt(g_max / g_i), g_i a Gershgorin bound of row i of the mass-normalised tangent stiffness
// at rest and g_max the largest over the free particles. Phases: the coarse particles ordered
// by their angle about the finest class's centre, cut into max_interval sectors of equal work,
// sector s giving phase bitreverse(s) mod k_i, so that the classes' ticks nest and a tick's
// work is about the mean. Deterministic: a function of the model and its arguments.
void build_rate_schedule(Model& model, int max_interval, double dt, double safety = kSubcyclingSafety);

}  // namespace palpate
