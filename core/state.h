#pragma once
// The mutable State of one simulation, in three parts:
//  - CarriedState: what one step hands to the next, and so what a Checkpoint copies
//    (positions, velocities, the indenter, the command, the contact set, the clock and
//    the health bookkeeping);
//  - StepOutputs: what a stage writes during a step for later stages and for the
//    caller (solver counts, the contact candidates, the sums the health checks read);
//    never needed by the next step;
//  - Workspace: scratch, preallocated so a step allocates nothing; never read across
//    stages or steps except as documented at the field.
// make_state() sizes all three from the Model alone, for every integrator, so a
// caller may switch Options::integrator between steps.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/model.h"
#include "core/options.h"
#include "core/thread_pool.h"
#include "core/types.h"

namespace palpate {

// What a step reports (health.h describes the checks behind each).
enum class StepStatus {
  ok,
  non_finite,             // NaN or Inf in the state
  contact_not_converged,  // the contact solve ran out of pivots
  energy_jump,            // kinetic energy far above the energy put in
  indenter_speed,         // the sphere moves faster than contact can follow
  penetration,            // a particle deep inside the sphere after the contact solve
  inverted_particle,      // det F <= 0 at a particle, without a volume term to undo it
};

// A failed health check (the state must go back to the last good one). A contact solve
// that ran out of pivots is reported but keeps the state.
inline bool is_fault(StepStatus s) { return s != StepStatus::ok && s != StepStatus::contact_not_converged; }

// The last failed health check: what, where, when, and by how much.
struct HealthReport {
  StepStatus status = StepStatus::ok;
  int64_t tick = 0;
  int particle = -1;   // the offending particle, -1 if none
  double value = 0.0;  // the measured quantity (J, m/s, m or det F)
  double limit = 0.0;  // its limit
};

// The health limits in force: Options::health, or derived from the model and the
// options where a limit is 0 (health_limits(), health.h).
struct HealthLimits {
  double energy_factor = 0.0;
  double energy_floor = 0.0;        // J
  double max_indenter_speed = 0.0;  // m/s
  double max_penetration = 0.0;     // m
  int inversion_window = 0;         // MLS particles whose det F is checked per step (0: none)
};

// Health-check bookkeeping carried from step to step (health.h).
struct HealthMonitor {
  double energy_input = 0.0;      // J: initial energy + work of the command and gravity so far
  double energy_budget = 0.0;     // J: the running maximum of energy_input
  double kinetic_energy = 0.0;    // J, body + indenter, at the last check
  Vec3 indenter_position{0, 0, 0};  // m, tool centre at the last check (work of the command)
  double gravity_potential = 0.0; // sum m_i g . x_i + M g . c at the last check (work of gravity), J
  int inversion_cursor = 0;       // first particle of the next inversion window
  int64_t inverted = 0;           // inverted particles seen (k_v > 0: tolerated, counted)
  HealthReport report;            // the last failure
};

// The command that presses the tool down (-z) with `newtons`: the one-dimensional
// command of the Hertz experiment.
inline Vec3 press_down(double newtons) { return Vec3(0.0, 0.0, -newtons); }

// Everything one step hands to the next. Copying it (Checkpoint) saves the state; the
// vectors keep their capacity, so a copy into a State of the same model allocates nothing.
struct CarriedState {
  Points position;  // 3 x n, x_i, m
  Points velocity;  // 3 x n, m/s

  // The tool: a rigid sphere with three translational degrees of freedom, kept inside
  // the model's tool workspace (Model::tool_workspace_min/max).
  Vec3 indenter_center{0, 0, 0};    // m
  Vec3 indenter_velocity{0, 0, 0};  // m/s
  // N, the external force on the tool in world coordinates: the real-time input. Pressing
  // a top face with F newtons is (0, 0, -F) (press_down()).
  Vec3 force_command{0, 0, 0};
  // m, the device position the virtual coupling pulls the tool toward (Options::coupling;
  // unused when the coupling is off).
  Vec3 tool_target{0, 0, 0};

  // The contact set of the last step (contact stage). The free motion of the next step
  // carries these forces as external forces (integrators.h).
  std::vector<int> contact_index;          // particles in contact (normal force > 0)
  std::vector<double> contact_normal_force;  // mu_i >= 0, N: the velocity-level multiplier of
                                             // particle contact_index[c] (momentum / dt, docs/physics.md §2)
  Points contact_force;                    // 3 x (capacity n): force on particle contact_index[c], N
  Vec3 indenter_contact_force{0, 0, 0};    // N, force of the body on the tool: -sum_c mu_c n_c

  double time = 0.0;  // s
  int64_t tick = 0;
  // n: the tick of particle i's last elastic update, of multirate symplectic Euler (integrators.h,
  // docs/physics.md (1.21)); its next update takes the ticks since. tick - 1 for all at a fresh
  // or carried-over state.
  std::vector<int64_t> elastic_update_tick;

  HealthMonitor health;
};

// The tool's part of a carried state (centre, velocity, command, coupling target): what two
// models stepped side by side with one tool share (a refocus, core/cloud_transfer.h).
inline void copy_tool(const CarriedState& from, CarriedState& to) {
  to.indenter_center = from.indenter_center;
  to.indenter_velocity = from.indenter_velocity;
  to.force_command = from.force_command;
  to.tool_target = from.tool_target;
}

// Written by a stage during a step, read by later stages of the same step or by the
// caller after it; the next step overwrites them.
struct StepOutputs {
  // Free motion (integrators.h).
  int cg_iterations = 0;  // implicit Euler: CG iterations of the free-motion solve
  // N, the virtual coupling's force on the tool at the end of the free motion,
  // k (target - c) - b v (0 when off); the device renders its negative.
  Vec3 coupling_force{0, 0, 0};
  // 1/2 sum m v^2 of the body and the sum of all coordinates, taken by the explicit
  // integrators' update pass (before contact) for the health checks; valid flags it.
  double free_motion_kinetic = 0.0, free_motion_position_sum = 0.0;
  bool free_motion_sums_valid = false;
  // Contact (contact.h).
  std::vector<int> contact_candidate;  // particles with negative free gap or in contact before
  int contact_iterations = 0;          // pivots of the contact solve
  double contact_max_penetration = 0.0;  // m, after the solve (linearised)
  // Implicit Euler's coupled contact (contact.h, docs/physics.md (2.17), (2.18)): the
  // compliance columns computed this step, the splitting iterations of the two LCPs, and
  // the CG solves and iterations all of it took.
  int contact_columns = 0;
  int contact_splitting_iterations = 0;
  int contact_cg_solves = 0;
  int contact_cg_iterations = 0;
};

// The compliance columns of implicit Euler's contact (contact.h; docs/physics.md (2.17)):
// for cached particles i, j with unit directions n_i, n_j, dt^2 n_i . (A^-1)_ij n_j, the
// body part of the Delassus operator W of (2.4). The one part of the Workspace read across
// steps: an approximation of W that only the cost of the contact solve depends on (the
// splitting (2.18) solves the LCP of each step's own A to the CG tolerance whatever it
// holds), so a Checkpoint leaves it alone and a fresh State starts without it.
struct ComplianceCache {
  std::vector<int> particle;      // slot -> particle (-1: free slot)
  std::vector<int> slot;          // n: particle -> slot (-1: not cached)
  std::vector<int64_t> last_used;  // slot -> the solve that last had its particle as a candidate
  Points direction;               // 3 x capacity: n_j, the unit force of each slot's column
  std::vector<double> entry;      // capacity x capacity, row-major: the entries above, m
  int capacity = 0;
  int64_t solves = 0;             // coupled contact solves so far
  double dt = 0.0, damping = 0.0;  // of the operator A the entries belong to
};

// Scratch memory owned by the state.
struct Workspace {
  Points force;                        // 3 x n
  Points rk_x[4], rk_v[4];             // RK4 stage slopes (symplectic Euler uses rk_v[0])
  Points x0, v0;                       // start-of-step copies
  // Implicit Euler
  Points cg_r, cg_p, cg_z, cg_Ap, rhs, dv;
  // The linearisation point of the tangent stiffness, written by the free motion and
  // read by the contact response of the same step (solid.h), 9 x n each (column-major
  // 3 x 3 per particle): the deformation gradient F_i (hex FEM: the element rotations)
  // and the law's factor its differential needs, S_i (St Venant-Kirchhoff, linear), R_i
  // (corotational) or F_i^-T (neo-Hookean).
  std::vector<double> tangent_F, tangent_law_factor;
  Points contact_response;             // 3 x n: A^-1 J^T (nu - p), implicit Euler's contact response (contact.cpp)
  ComplianceCache compliance;          // read across steps (see ComplianceCache)
  // Contact
  std::vector<int> candidate_slot;     // n, candidate slot of each particle, -1 if none
  std::vector<double> previous_multiplier;  // m, previous contact force along this step's normal
  Points previous_force;               // 3 x n capacity, previous contact force vectors
  std::vector<double> gap;             // free gaps, m
  Points normal;                       // 3 x n capacity, unit normals from the sphere centre
  std::vector<double> delassus;        // m x m, row-major: implicit Euler's W~ (2.17)
  std::vector<double> delassus_diagonal;  // m: D of the explicit integrators' W = D + U U^T (2.4)
  std::vector<double> delassus_factor;    // 3 m: U, row a at 3a
  std::vector<double> delassus_product;   // m: W x
  std::vector<double> pivot_rhs;          // m: the active set's right-hand side, then its multipliers
  std::vector<double> multiplier;      // m
  std::vector<double> solve_buffer;    // scratch of the active-set solve
  std::vector<int> active;             // active-set membership (0/1 per candidate)
  std::vector<int> members;            // indices of the active candidates
  std::vector<int> infeasible;         // m: the candidates a pivot flips
  // The threads of the force loops (Options' integrator.threads; use_threads()). Not copied
  // with the State: a copy makes its own pool at its first step.
  WorkerThreads threads;
  std::vector<double> splitting;       // 4 m: implicit Euler's splitting iterates (contact.cpp)
  std::vector<int> guess;              // m: the active set pivoting starts from
  // Multirate symplectic Euler: the coarse particles near the tool this tick (ascending), the
  // blocks their domains add to the tick's schedule, the tick's blocks with them (ascending).
  std::vector<int> subcycle_near, subcycle_extra, subcycle_blocks;
  std::vector<uint8_t> subcycle_block_listed;  // blocks: 1 while listed in subcycle_extra
};

struct State : CarriedState {
  StepOutputs out;
  Workspace work;
};

// The rest state of a model (positions at rest, the indenter at its start, the scene's
// initial force command), all memory sized for every integrator; the health budget
// starts from it under `opt` (its gravity).
State make_state(const Model& model, const Options& opt);

// Makes state.work.threads opt.integrator.threads strong for the model (step() calls it:
// a change of the option between steps starts or stops worker threads there, once).
void use_threads(const Model& model, const Options& opt, State& state);

}  // namespace palpate
