#pragma once
// The constant Model: the reference configuration and everything precomputed
// from it. Built once from a Scene (build_model); never changed by a step.
// Shapes: n = particle_count, nnz = total number of weighted neighbours.
#include <cstdint>
#include <string>
#include <vector>

#include "core/hex_fem.h"
#include "core/rate_schedule.h"
#include "core/scene.h"
#include "core/types.h"

namespace palpate {

struct Model {
  // What it was built from (the Scene itself stays the caller's: options_of(scene) gives
  // the step options, and nothing here may be edited to change them).
  std::string name;    // the scene's name
  std::string source;  // the scene's file (or "<rpc scene>"), for messages
  SolidKind solid = SolidKind::mls;  // which elastic model the particles (nodes) belong to
  DistributionType distribution = DistributionType::grid;  // how the particles were placed

  int particle_count = 0;
  Points rest_position;  // 3 x n, X_i, m

  // Support domains, CSR (neighbours with non-zero weight only; the particle itself excluded).
  std::vector<int> neighbor_offset;      // n+1
  std::vector<int> neighbor_index;       // nnz
  Points gradient_weight;                // 3 x nnz, d_j = A_i^-1 x_ij w_ij; d_i = -sum_j d_j is implied
  std::vector<double> rest_correction;   // 9 x n (column-major 3x3 per particle): I - sum_j X_ij d_j^T,
                                         // zero unless A_i was regularised; makes F(X) = I exactly
  std::vector<double> support_radius;    // n, h_i = alpha * mean neighbour distance, m

  // Mass and volume.
  std::vector<double> mass;              // n, kg (with the mass floor (1.18) when mls.mass_floor > 0)
  int mass_floor_raised = 0;             // particles whose mass the floor (1.18) raised
  double mass_floor_added = 0.0;         // kg, the mass it added (over all particles)
  std::vector<double> inverse_mass;      // n, 1/kg; 0 for fixed particles (projected boundary condition)
  std::vector<double> volume;            // n, v_i, m^3
  std::vector<uint8_t> fixed;            // n, 1 = fixed particle
  int fixed_count = 0;
  double free_mass = 0.0;                // sum of m_i over the free particles, kg

  // Blocked copy of the support domains for the vectorised force loop (mls_loops.h,
  // core/force_blocks.h). Block b holds four particles (lanes 0..3): 4b ... 4b+3, or as a
  // subcycled model's schedule regroups them (core/rate_schedule.h); the last block's lanes
  // beyond the particle count are padding with zero volume and zero weights. Slot s of a
  // block holds the s-th neighbour of each of its four particles; shorter neighbour lists
  // are padded to the block's longest with d = 0 and j = the lane's own particle, which adds
  // nothing.
  static constexpr int block_width = 4;
  struct NeighborSlot {
    alignas(32) double d[3][block_width];  // d_j: component c of lane l at d[c][l]
    int j[block_width];                    // neighbour particle of each lane
  };
  struct ParticleBlock {
    alignas(32) double rest_correction[9][block_width];  // C_i entry k (column-major 3x3) of lane l
    double self_weight[3][block_width];                  // d_i = -sum_j d_j, as NeighborSlot::d
    double volume[block_width];                          // v_i, m^3; 0 in padding lanes
    double lame_lambda[block_width];                     // particle_lambda of lane l (padding: the matrix's)
    double lame_mu[block_width];                         // particle_mu of lane l
    int slot_begin = 0, slot_end = 0;                    // its slots in block_slots
    int particle[block_width] = {};                      // lane l's particle (padding: the last lane's)
    int lanes = 0;                                       // lanes holding a particle (4 but in the last block)
  };
  std::vector<ParticleBlock> blocks;      // ceil(n / 4)
  std::vector<NeighborSlot> block_slots;  // sum over blocks of the longest neighbour list

  // Hourglass control (empty when the scene's mls.hourglass == 0). On a cloud refined in-process
  // only the particles whose support holds a particle the refinement added have it (kappa_i = 0
  // elsewhere: docs/physics.md (1.9)).
  std::vector<double> hourglass_weight;  // nnz, kappa_i * w_ij, N/m
  Points neighbor_rest_offset;           // 3 x nnz, X_ij = X_j - X_i (hourglass only)
  // Its blocked copy (docs/physics.md (1.9a)), parallel to block_slots and blocks; padding
  // slots and lanes hold zeros. Per slot k_ij = kappa_i w_ij and e_ij = k_ij X_ij; per
  // particle H_i = sum_j k_ij X_ij X_ij^T and e_i = sum_j e_ij.
  struct HourglassSlot {
    alignas(32) double e[3][block_width];  // e_ij, N: component c of lane l at e[c][l]
    double k[block_width];                 // k_ij, N/m
  };
  struct HourglassBlock {
    alignas(32) double H[6][block_width];  // H_i entries (0,0), (1,1), (2,2), (0,1), (0,2), (1,2), N m
    double e_sum[3][block_width];          // e_i, N
    bool active = false;                   // a lane has hourglass control (else the loops skip its terms)
  };
  std::vector<HourglassSlot> block_hourglass_slots;  // as block_slots (hourglass only)
  std::vector<HourglassBlock> block_hourglass;       // as blocks (hourglass only)

  // The undeformed boundary surface (core/surface.h): 3 x T particle indices, each triangle
  // counterclockwise seen from outside. Mesh clouds: the mesh's boundary faces; lattices
  // (grid, jittered, graded, the hex FEM's): the box faces, two triangles per face cell;
  // node_file clouds: none (0 columns).
  Eigen::Matrix<int, 3, Eigen::Dynamic> surface_triangles;

  // Multirate symplectic Euler's schedule (core/rate_schedule.h), built for the scene's
  // integrator.max_interval (period 1 and empty: one rate).
  RateSchedule rate_schedule;

  // Hexahedral FEM (solid == hex_fem only; particles are the lattice nodes).
  HexMesh hex;

  // Material: the only copy (the scene's material section is not kept).
  // lame_lambda, lame_mu, density are the matrix (bulk) material's; the particle_ arrays
  // are each particle's own (MLS: its cell blended by volume fraction over the scene's
  // material.inclusions, (1.16); hex FEM: the node's lattice cell, used for the masses and
  // the time-step envelope, while each element carries its own K_e). Homogeneous: all equal
  // to the matrix's.
  double lame_lambda = 0.0;       // Pa
  double lame_mu = 0.0;           // Pa
  double density = 0.0;           // rho, kg/m^3
  std::vector<double> particle_lambda;   // n, Pa
  std::vector<double> particle_mu;       // n, Pa
  std::vector<double> particle_density;  // n, rho_i, kg/m^3 (m_i = rho_i v_i on lattice and mesh volumes)
  double volume_stiffness = 0.0;  // k_v, Pa
  MaterialLaw law = MaterialLaw::stvk;  // MLS material law (scene material.law)

  // Indenter (its mass is an option: Options::indenter_mass).
  double indenter_radius = 0.0;   // m
  Vec3 indenter_start{0, 0, 0};   // initial centre, m
  double initial_force_command = 0.0;  // N pressing down, the scene's indenter.force: State::force_command
                                       // = press_down(it) at rest
  // The box the tool's centre is kept in (scene indenter.workspace; default: the body's
  // bounding box grown by two radii on every side), m. A centre that the free motion
  // takes outside is put back on the box, and its outward velocity removed.
  Vec3 tool_workspace_min{0, 0, 0}, tool_workspace_max{0, 0, 0};
  double touch_height = 0.0;      // z of the centre when the sphere, coming down over indenter_start's x, y,
                                  // first touches the undeformed surface: surface_triangles when there are
                                  // any (docs/physics.md (2.16)), else the highest particle under it + R, m

  // Diagnostics of the build.
  int regularized_count = 0;      // particles whose moment matrix needed regularisation
  double worst_condition = 0.0;   // largest cond(A_i) before regularisation
  double total_volume = 0.0;      // sum v_i, m^3 (compare with box_volume)
  double box_volume = 0.0;        // m^3: the scene's box; a mesh body without /body/box: the mesh's volume
  double min_spacing = 0.0;       // smallest nearest-neighbour distance (FEM: element edge), m
  // The stable step from the model's highest frequency (time_step.h, spectral_time_step) with
  // the scene's integrator: computed by build_model only for a refined mesh whose dt the
  // spacing estimate refuses (MLS, explicit integrators), else 0 (not computed), s.
  double spectral_time_step = 0.0;
  double max_spacing = 0.0;       // largest nearest-neighbour distance (FEM: element edge), m
  double wave_speed = 0.0;        // fastest p-wave speed present, max_i sqrt((lambda_i + 2 mu_i) / rho_i), m/s
  int64_t mesh_tetrahedra = 0;    // mesh clouds: tetrahedra read (0 otherwise)
  int64_t mesh_unused_nodes = 0;  // mesh clouds: TetGen mid-edge nodes dropped (other unused nodes are refused)
  // Integration constraint sum_i v_i g_ij = 0 at interior particles (MLS only):
  // max residual relative to the mean |v_i g_ij|, of the plain MLS weights and of
  // the weights in use (equal unless mls.integration is "consistent").
  double integration_residual_nodal = 0.0;
  double integration_residual = 0.0;
  double integration_correction = 0.0;  // ||delta|| / ||g|| of the consistent correction
};

// Builds the model a scene describes. Throws SceneError / std::runtime_error
// with an actionable message on a scene that cannot be built, or whose options
// (options_of(scene)) the model cannot run (check_options, time_step.h).
Model build_model(const Scene& scene);
// The same from the scene's cloud made already (make_node_cloud, or refined_mesh_cloud
// toward another site: a refocus), so that the caller keeps its tetrahedra.
struct NodeCloud;
Model build_model(const Scene& scene, const NodeCloud& cloud);

}  // namespace palpate
