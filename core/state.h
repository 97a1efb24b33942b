#pragma once
// The mutable State: everything a step changes, plus preallocated scratch so a
// step allocates nothing. make_state() gives the rest state of a Model.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/model.h"
#include "core/types.h"

namespace palpate {

// Scratch memory owned by the state (never read across steps).
struct Workspace {
  Points force;                        // 3 x n
  Points rk_x[4], rk_v[4];             // RK4 stage slopes
  Points x0, v0;                       // start-of-step copies
  // Written by the explicit free-motion stages for the health checks (health.h):
  // 1/2 sum m v^2 of the body and sum of all coordinates after the update (before contact).
  double free_motion_kinetic = 0.0, free_motion_position_sum = 0.0;
  bool free_motion_sums_valid = false;
  // Implicit Euler (allocated only for that integrator)
  Points cg_r, cg_p, cg_z, cg_Ap, rhs, dv;
  std::vector<double> cached_F, cached_S;  // 9 x n each: linearisation point of the tangent stiffness
  Points contact_response;             // 3 x (n * m): A^-1 J^T columns of the implicit contact compliance
  // Contact
  std::vector<int> candidate;          // particles with negative free gap or in contact before
  std::vector<int> candidate_slot;     // n, candidate slot of each particle, -1 if none
  std::vector<double> previous_multiplier;  // m, previous contact force along this step's normal
  Points previous_force;               // 3 x n capacity, previous contact force vectors
  std::vector<double> gap;             // free gaps, m
  Points normal;                       // 3 x n capacity, unit normals from the sphere centre
  std::vector<double> delassus;        // m x m, row-major
  std::vector<double> multiplier;      // m
  std::vector<double> solve_buffer;    // scratch of the active-set solve
  std::vector<int> active;             // active-set membership (0/1 per candidate)
  std::vector<int> members;            // indices of the active candidates
};

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

// The health limits in force (the scene's "health" fields, or derived from the model).
struct HealthLimits {
  double energy_factor = 0.0;
  double energy_floor = 0.0;        // J
  double max_indenter_speed = 0.0;  // m/s
  double max_penetration = 0.0;     // m
  int inversion_window = 0;         // MLS particles whose det F is checked per step (0: none)
};

// Health-check bookkeeping carried from step to step (health.h).
struct HealthMonitor {
  HealthLimits limits;            // set by reset_health()
  double energy_input = 0.0;      // J: initial energy + work of the command and gravity so far
  double energy_budget = 0.0;     // J: the running maximum of energy_input
  double kinetic_energy = 0.0;    // J, body + indenter, at the last check
  double indenter_z = 0.0;        // m, indenter height at the last check (work of the command)
  double gravity_potential = 0.0; // sum m_i g . x_i + M g . c at the last check (work of gravity), J
  int inversion_cursor = 0;       // first particle of the next inversion window
  int64_t inverted = 0;           // inverted particles seen (k_v > 0: tolerated, counted)
  HealthReport report;            // the last failure
};

struct State {
  Points position;  // 3 x n, x_i, m
  Points velocity;  // 3 x n, m/s

  Vec3 indenter_center{0, 0, 0};  // m; moves along z only
  double indenter_velocity = 0.0; // m/s along z
  double force_command = 0.0;     // N pressing the indenter down (-z); the real-time input

  // Contact, written by the contact stage each step.
  std::vector<int> contact_index;      // particles in contact (multiplier > 0)
  std::vector<double> contact_multiplier;  // lambda_i >= 0, N (normal force magnitude)
  Points contact_force;                // 3 x (contact count capacity n): force on particle, N
  double indenter_contact_force = 0.0; // z force of the body on the indenter, N (positive up)
  int contact_iterations = 0;          // pivots of the last contact solve
  double contact_max_penetration = 0.0;  // m, after the solve (linearised)

  double time = 0.0;  // s
  int64_t tick = 0;
  int cg_iterations = 0;  // implicit Euler, last step (free motion solve)

  HealthMonitor health;

  Workspace work;
};

State make_state(const Model& model);

}  // namespace palpate
