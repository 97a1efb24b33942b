#pragma once
// Quasi-static solve (docs/physics.md §5): the rest state under a commanded indenter
// force, found directly instead of by a dynamic settle.
//
// For the linear hexahedral FEM it is exact: the stiffness K over the free DOFs
// is assembled and factorised once (sparse Cholesky, CHOLMOD), and the frictionless
// contact of a rigid sphere, linearised as in Hertz theory (vertical gaps of the
// top-face nodes under the sphere, small strain), is a Signorini problem on the
// compliance C = K^-1 of those nodes:
//   w = h - d + C p >= 0,  p >= 0,  p . w = 0,  sum p = F,
// with h_i the undeformed gap of node i when the sphere touches the surface
// (d = 0), d the indentation (docs/physics.md §2) and p the nodal contact forces. It is
// solved by an active-set method: for a fixed active set A the conditions w_A = 0
// and sum p = F give d and p_A in closed form, nodes with p < 0 leave A, nodes with
// w < 0 join it, until neither happens. Columns of C are computed only for nodes
// that become active, so a sweep of forces reuses one factorisation.
//
// For the nonlinear models (MLS, corotational FEM) the rest state is found by
// pseudo-transient continuation: linearly implicit Euler steps with the velocity
// cleared after every step and a time step that grows as the residual falls (each
// step is a Newton step regularised by M / dt^2, with the exact coupled contact
// solve of the implicit integrator), until the contact force balances the command
// and the free particles' residual force is below tolerance.
#include <memory>
#include <string>
#include <vector>

#include <Eigen/SparseCore>

#include "core/model.h"
#include "core/options.h"
#include "core/state.h"

namespace palpate {

struct StaticSolution {
  bool converged = false;
  double indentation = 0.0;     // d, m (docs/physics.md §2)
  double contact_force = 0.0;   // sum of the contact forces on the body, N
  int active_count = 0;         // nodes in contact
  int iterations = 0;           // active-set changes (linear) or continuation steps (nonlinear)
  double max_penetration = 0.0; // largest violation of w >= 0 left, m
  std::string message;          // why it did not converge
};

// A linear elastic body for the same solve, from any discretisation (the linear tetrahedra
// of analysis/tet_reference.h): the lower triangle (row >= column) of its stiffness over all
// 3n DOFs (3 i + c; entries on fixed nodes' DOFs are dropped, duplicates summed), the
// rest positions, which nodes are fixed, the contact candidates (free surface nodes the
// sphere may touch) and the sphere: radius, site (x, y) and the height of its centre when it
// first touches a candidate (each candidate's gap h_i = touch_height - sqrt(R^2 - r_i^2) - z_i).
struct LinearBody {
  Points rest_position;
  std::vector<uint8_t> fixed;
  std::vector<Eigen::Triplet<double>> stiffness_lower;
  std::vector<int> candidate;  // node indices, each free and within R of the site in (x, y)
  double indenter_radius = 0.0;
  double site_x = 0.0, site_y = 0.0;
  double touch_height = 0.0;
};

// Linear FEM: the factorised stiffness and the compliance columns computed so far.
class LinearStaticContact {
 public:
  // Assembles and factorises K; throws std::runtime_error when the model is not the
  // linear hex FEM or K is singular (too few fixed faces).
  explicit LinearStaticContact(const Model& model);
  // The same for a body given by its stiffness (solve's `state` must then be null: there
  // is no Model to write a State of). Throws std::runtime_error when K is singular, and
  // std::invalid_argument when a candidate is fixed, outside the sphere's footprint or
  // its gap is negative, or there is none.
  explicit LinearStaticContact(LinearBody body);
  ~LinearStaticContact();
  LinearStaticContact(const LinearStaticContact&) = delete;
  LinearStaticContact& operator=(const LinearStaticContact&) = delete;

  // Rest state under `force` (N, pressing down). With `state`, also writes the
  // positions, the indenter centre, the contact forces and zero velocities into it.
  StaticSolution solve(double force, State* state = nullptr);

  int free_dofs() const;
  int candidate_count() const;   // top-face nodes under the sphere
  int columns_computed() const;  // compliance columns (one sparse solve each)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Nonlinear models (and any other): pseudo-transient continuation from the state
// given (implicit Euler steps of growing length with opt's dt as the first), then,
// if it stalls, the damped dynamics of `opt` until `rest` holds (press_to_rest).
// `residual_tolerance` is relative to the commanded force.
StaticSolution relax_to_rest(const Model& model, const Options& opt, const RestSpec& rest, State& state, double force,
                             double residual_tolerance = 1e-6, int max_steps = 500);

// The rest state with the tool HELD at `tool_position` (m; any model): the static
// equilibrium of the body against a sphere that does not move, the truth a finite
// difference of the local contact model (core/contact_stiffness.h) is taken against.
// Pseudo-transient continuation as relax_to_rest, with the tool infinitely heavy and put
// back at `tool_position` with zero velocity after every step, no command, health checks
// off (the continuation is not dynamics), the contact solved to `contact_tolerance` (m),
// until the largest net force on a free particle is below `residual_tolerance` times the
// force on the tool (times 1 mN without contact).
// Writes the state's positions, zero velocities, the tool centre and the contact set;
// contact_force is the z component of the force of the body on the tool.
StaticSolution relax_to_rest_at(const Model& model, const Options& opt, State& state, const Vec3& tool_position,
                                double residual_tolerance = 1e-9, double contact_tolerance = 1e-12,
                                int max_steps = 500);

// Whether a model has the exact linear solve (the linear hex FEM).
bool has_linear_static_solve(const Model& model);

}  // namespace palpate
