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

enum class StepStatus { ok, non_finite, contact_not_converged };

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

  Workspace work;
};

State make_state(const Model& model);

}  // namespace palpate
