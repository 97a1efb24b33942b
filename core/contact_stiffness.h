#pragma once
// The local contact model (docs/physics.md §2, "The local contact model", (2.7)-(2.15)):
// the linearisation of the contact force on the tool about the tool's current centre,
//
//   F(x) ~ F0 + K (x - x0),   |x - x0| <= valid_radius,
//
// for a renderer (a haptic servo loop) that runs faster than the simulation. K = dF/dx
// is the quasi-static stiffness of the contact for the current active set: what a finite
// difference of two static solves with the tool held at nearby positions gives, not the
// one-step inertial response. For a tool displacement dc the active particles stay on
// the sphere (2.7) and the free particles stay in equilibrium (2.8), the contact
// multipliers at the active particles being the only new loads, with the stiffness of
// the normals' rotation (2.9). The particles' displacement solves a symmetric system on
// the subspace of admissible displacements (2.10), by projected conjugate gradients:
// three solves (dc = e_x, e_y, e_z), each warm-started from the previous call's, run in
// lockstep so that one sweep of the tangent (elastic_force_differentials) serves all three. The
// reactions (2.11) and the normals' rotation give dF (2.12); K is symmetric (2.13). The
// validity radius (2.14), (2.15) is how far the tool may move before the active set
// changes, to first order.
//
// A stage of its own: it reads a Model and a CarriedState and changes neither of
// them, so a caller may run it on its own thread on a copy of the state. Each instance
// owns its scratch (sized for the worst case at construction; evaluate() allocates
// nothing) and its warm starts; instances share nothing.
#include <cstdint>
#include <vector>

#include "core/model.h"
#include "core/state.h"
#include "core/types.h"

namespace palpate {

// The force of the body on the tool near x0 = origin:
// F(x) = force + stiffness (x - origin) for |x - origin| <= valid_radius.
struct LocalContactModel {
  Vec3 origin{0, 0, 0};           // m, the tool centre x0 (State::indenter_center)
  Vec3 force{0, 0, 0};            // N, F0 = State::indenter_contact_force
  Mat3 stiffness = Mat3::Zero();  // N/m, K = dF/dx (2.12), column j = dF for dc = e_j
  double valid_radius = 0.0;      // m (2.14), (2.15)
  // Out of contact only, when ContactStiffnessSettings::touch_stiffness is set: K at the
  // moment the nearest free particles touch (2.20), for a renderer to use from the first
  // contact on until a K computed in contact arrives (zero when not computed).
  Mat3 touch_stiffness = Mat3::Zero();  // N/m
  int touch_count = 0;                  // the particles it assumes touching (0: not computed)
  int64_t tick = 0;               // the state's tick it was computed at
  int active_count = 0;           // particles in contact (the active set of (2.7))
  int cg_iterations = 0;          // projected CG iterations of the three solves (2.10)
  bool reused = false;            // the state was the last evaluation's: its result, recomputed nothing
  bool converged = true;          // all three solves met the tolerance
  // Which bound set valid_radius, and where and along which direction it is reached.
  enum class Limit {
    no_contact,  // no active particle: the distance to the nearest free particle (2.15)
    entering,    // a particle outside the active set reaches the sphere (2.14)
    leaving,     // an active particle's multiplier reaches zero (2.14)
  };
  Limit limited_by = Limit::no_contact;
  int limiting_particle = -1;           // the particle that enters or leaves (-1: none)
  Vec3 limiting_direction{0, 0, 0};     // unit tool displacement that reaches it first
};

const char* to_string(LocalContactModel::Limit);

// The projected CG of (2.10): relative residual ||r|| <= tolerance ||b|| per solve,
// at most max_iterations iterations per solve.
struct ContactStiffnessSettings {
  double tolerance = 1e-6;
  int max_iterations = 2000;
  // Out of contact, also compute LocalContactModel::touch_stiffness (one more set of
  // solves per evaluation without contact).
  bool touch_stiffness = false;
  // Nodes per axis of the coarse lattice of the preconditioner's coarse correction (2.21),
  // 2 ... 12, at most about the cube root of the particle count over 3; 0: block Jacobi alone.
  int coarse_per_axis = 6;
};

// What the server's renderer uses (server/local_model.h): relative residual 10^-2. K then
// agrees with a 10^-10 solve to a few 10^-4 of its largest entry on the shipped scenes (a
// K error e moves a rendered force by e K dx, far below the rendering error of a 4 ms
// model; palpate-bench-contact-stiffness prints it). While the tool moves the worker's
// warm start is far, and an evaluation is nearly a cold one: on the graded cube 36
// iterations with the coarse correction (2.21) (67 without; 100 and 113 at 10^-3), so K
// is that much younger, and its age, not this error, is what a renderer feels
// (docs/verification.md, "Multirate haptics").
// Verification keeps the default 10^-6.
// It also computes the stiffness at first touch: a worker that needs tens of model steps
// for an evaluation in contact would otherwise leave the first tens of milliseconds of
// every press without one (docs/verification.md, "Multirate haptics").
inline constexpr ContactStiffnessSettings kRenderingStiffness{1e-2, 2000, true, 6};

class ContactStiffness {
 public:
  // Sizes every scratch array for `model` (n particles, up to n active) and builds the
  // preconditioner of (2.10) from the model's reference tangent: its 3x3 diagonal blocks
  // and the coarse operator of (2.21) (one tangent sweep per three coarse unknowns:
  // 216 sweeps for the default 6^3 lattice).
  // Throws std::invalid_argument on a tolerance outside (0, 1), max_iterations < 1, or
  // coarse_per_axis outside {0} and [2, 12].
  explicit ContactStiffness(const Model& model, ContactStiffnessSettings settings = {});

  // The local contact model at `state` (its positions, tool centre, contact set and
  // multipliers), whatever the Options it was stepped with: K is quasi-static (no dt,
  // damping or masses), for the tool's three translations whatever its guide, and a
  // constant load such as gravity does not enter it. `model` must be the one the
  // instance was built for. Throws std::invalid_argument when the state does not belong
  // to the model.
  LocalContactModel evaluate(const Model& model, const CarriedState& state);

  // Forgets the warm starts: the next evaluate() starts its solves from zero (after a
  // restored checkpoint, a new scene state, or to time a cold evaluation).
  void clear_warm_start();
  // A state that is the last evaluation's to within 10^-6 of the smallest particle spacing
  // (every position, the tool's centre, and the depth of the touch's lookahead), with the
  // same contact set and multipliers within 10^-6 of their largest, gets the last result
  // again (LocalContactModel::reused, with the new tick) without a tangent sweep: a tool
  // held still, or away from a body at rest, costs a comparison, not an evaluation.

  // With touch_stiffness: how long (s) the stiffness at first touch will serve a renderer
  // after the touch, until an evaluation in contact replaces it (about a worker's
  // evaluation and a half). The touch is then taken at the depth the tool reaches
  // halfway through that time at its current approach speed (2.22); 0 (the default,
  // and what a headless session uses): at the touch itself (2.20). Throws
  // std::invalid_argument on a negative or non-finite value.
  void set_touch_lookahead(double seconds);
  // The coarse lattice of the preconditioner (2.21) as built: nodes per axis (0: none).
  Eigen::Vector3i coarse_lattice() const { return coarse_lattice_; }
  double touch_lookahead() const { return touch_lookahead_; }

  // The particles' quasi-static response of the last evaluate() to a unit tool
  // displacement e_j (j = 0, 1, 2): dx/dc_j, 3 x n, zero at fixed particles (and all
  // zero after an evaluation without contact, or the first touch's response with touch_stiffness).
  // Also the next call's warm start.
  const Points& displacement_response(int j) const { return response_[j]; }
  // The multiplier increments of the last evaluate() (2.11): d mu_a / dc (N/m, component j
  // for dc = e_j) of the a-th active particle (the order of CarriedState::contact_index).
  Vec3 multiplier_response(int a) const { return multiplier_response_.row(a).transpose(); }

 private:
  // out[q] = P (K_b - G) P w[q] (2.10) for q < count, the tangent products in one sweep.
  void apply_operator(const Model& model, int count, const Points* const* w, Points* const* out);
  // z[q] = P D^-1 P r[q] + P T A_c^-1 T^T P r[q] (2.21) for q < count (r in the subspace):
  // the coarse solve of all directions in one pass over A_c^-1.
  void precondition(int count, const Points* const* r, Points* const* z);
  // The coarse lattice of (2.21) over the reference configuration, its interpolation and
  // the factorised coarse operator T^T K_0 T (K_0 the tangent at rest, tangent_ on return).
  void build_coarse_correction(const Model& model, int per_axis);
  void project(Points& w) const;                                          // w <- P w
  // The three projected CGs of (2.10), b_[j] -> response_[j] (which holds the warm start), in
  // lockstep: each its own alpha, beta and stopping test, the products of the directions still
  // iterating in one call. Adds each direction's iterations to `iterations`.
  void solve(const Model& model, int& iterations, bool& converged);
  // The active set: emptied, then one particle at a time (multiplier mu, normal nrm, |x_i - c| = r).
  void begin_active_set();
  void add_active(int i, double mu, const Vec3& nrm, double r);
  // K of (2.10)-(2.12) for the current active set at `state`; response_ and
  // multiplier_response_ are its solution.
  Mat3 stiffness_of_active_set(const Model& model, const CarriedState& state, int& iterations, bool& converged);

  int n_ = 0;
  ContactStiffnessSettings settings_;
  double touch_lookahead_ = 0.0;  // s (2.22)
  // The last evaluation's input and result (same_as_last).
  bool have_last_ = false;
  Points last_position_;
  Vec3 last_centre_{0, 0, 0};
  double last_touch_depth_ = 0.0;
  std::vector<int> last_contact_index_;
  std::vector<double> last_multiplier_;
  LocalContactModel last_;
  // Whether `state` is the last evaluation's (see clear_warm_start); keeping this one's.
  bool same_as_last(const Model& model, const CarriedState& state) const;
  void remember(const CarriedState& state, const LocalContactModel& result);
  // d* of (2.22): half the tool's approach speed toward `nearest` (unit) times the lookahead.
  double touch_depth(const CarriedState& state, const Vec3& nearest) const;
  // evaluate() without the check for an unchanged state.
  LocalContactModel evaluate_anew(const Model& model, const CarriedState& state);
  Workspace tangent_;  // the tangent's linearisation point (solid.h): tangent_F / tangent_law_factor and the
                       // force loops' scratch (threads) are used
  std::vector<uint8_t> movable_;        // n: 1 = free particle, 0 = fixed
  std::vector<Mat3> diagonal_;          // n: D_i, the reference tangent's 3x3 diagonal block
  std::vector<Mat3> diagonal_inverse_;  // n: D_i^-1 (0 at fixed particles)
  // The active set of the current evaluation.
  std::vector<int> active_;             // particle indices
  std::vector<int> slot_;               // n: position of a particle in active_, -1 if not active
  Points normal_;                       // 3 x (capacity n): n_a (2.2)
  std::vector<double> multiplier_;      // mu_a, N
  std::vector<double> geometric_;       // mu_a / |x_a - c|, N/m: the normal rotation's stiffness (2.8)
  std::vector<Mat3> active_precond_;    // projected inverse blocks at the active particles
  // The coarse correction (2.21): trilinear interpolation T from a coarse lattice (nodes at
  // the quantiles of the particles' coordinates along each axis), 8 nodes per particle.
  int coarse_nodes_ = 0;                   // 0: none
  Eigen::Vector3i coarse_lattice_{0, 0, 0};  // nodes per axis
  std::vector<int> coarse_node_;           // 8n: the coarse nodes of particle i's cell
  std::vector<double> coarse_weight_;      // 8n: their trilinear weights (0 at fixed particles)
  Eigen::MatrixXd coarse_inverse_;         // A_c^-1, A_c = T^T K_0 T (3 coarse_nodes_ unknowns)
  Eigen::Matrix<double, Eigen::Dynamic, 3> coarse_rhs_, coarse_solution_;  // scratch: T^T r, A_c^-1 T^T r
  // Scratch of the solves.
  Points u_p_[3], b_[3], r_[3], z_[3], p_[3], Ap_[3], df_[3];  // per direction dc = e_j
  Points response_[3];  // dx/dc_j of the last call, the warm starts
  Eigen::Matrix<double, Eigen::Dynamic, 3> multiplier_response_;
};

}  // namespace palpate
