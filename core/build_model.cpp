// Model construction: node cloud -> support domains -> MLS precomputation
// (masses, volumes, moment matrices, gradient weights d_j) -> boundary
// conditions -> indenter placement. Everything that depends only on the
// reference configuration is computed here, once.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <spdlog/spdlog.h>

#include "core/boundary.h"
#include "core/consistent_integration.h"
#include "core/force_blocks.h"
#include "core/time_step.h"
#include "core/kernel.h"
#include "core/material_field.h"
#include "core/model.h"
#include "core/neighbors.h"
#include "core/node_cloud.h"
#include "core/surface.h"

namespace palpate {

namespace {

// Robust inverse of a symmetric positive semi-definite moment matrix: eigenvalues
// below `floor_ratio * largest` are raised to that floor. Returns true when it had to.
bool regularized_inverse(const Mat3& A, double floor_ratio, Mat3& A_inv, double& condition) {
  Eigen::SelfAdjointEigenSolver<Mat3> eig(A);
  Vec3 ev = eig.eigenvalues();  // ascending
  const double largest = ev[2];
  condition = ev[0] > 0 ? largest / ev[0] : INFINITY;
  const double floor = std::max(floor_ratio * largest, 1e-300);
  bool raised = false;
  for (int c = 0; c < 3; ++c)
    if (ev[c] < floor) {
      ev[c] = floor;
      raised = true;
    }
  A_inv = eig.eigenvectors() * ev.cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
  return raised;
}

// Height of the indenter centre when the sphere (centre above (cx, cy)) first
// touches a particle of the undeformed body; also the height of the undeformed
// surface under the sphere (the highest particle within its footprint).
double first_touch_height(const Points& X, double cx, double cy, double radius, double& surface) {
  double top = -INFINITY;
  surface = -INFINITY;
  for (Eigen::Index i = 0; i < X.cols(); ++i) {
    const double r2 = (X(0, i) - cx) * (X(0, i) - cx) + (X(1, i) - cy) * (X(1, i) - cy);
    if (r2 >= radius * radius) continue;
    top = std::max(top, X(2, i) + std::sqrt(radius * radius - r2));
    surface = std::max(surface, X(2, i));
  }
  return top;
}

// Material (Lame parameters from E, nu).
void set_material(Model& m, const MaterialSpec& mat) {
  const LameParameters lame = lame_parameters(mat.young_modulus, mat.poisson_ratio);
  m.lame_lambda = lame.lambda;
  m.lame_mu = lame.mu;
  m.volume_stiffness = mat.volume_stiffness;
  m.law = mat.law;
  m.density = mat.density;
  m.wave_speed = std::sqrt((m.lame_lambda + 2 * m.lame_mu) / mat.density);
}

// The per-particle material (material_field.h): each particle's cell (its lattice cell when
// `on_lattice`, the cloud is a grid or graded_grid one or the hex FEM's bricks, and the cloud
// is the whole lattice; else a cube of volume v_i) blended over the inclusions (1.16); masses
// m_i = rho_i v_i (the volumes are the matrix's: the masses scale by rho_i / rho). `source`
// names the scene in errors. Sets Model::wave_speed to the fastest p-wave present.
void set_particle_materials(Model& m, const MaterialSpec& material, bool on_lattice, const NodeCloud& cloud,
                            const std::string& source) {
  Points cell_min, cell_max;
  const bool lattice = on_lattice && cloud.lattice_size.prod() == m.particle_count;
  if (lattice)
    lattice_cells(m.rest_position, cloud.lattice_size, cell_min, cell_max);
  else
    cube_cells(m.rest_position, m.volume, cell_min, cell_max);
  MaterialField field = material_field(material, cell_min, cell_max);
  blend_group_inclusions(material, cloud, source, field);
  m.particle_lambda = std::move(field.lambda);
  m.particle_mu = std::move(field.mu);
  m.particle_density = std::move(field.density);
  m.wave_speed = 0.0;
  for (int i = 0; i < m.particle_count; ++i) {
    if (m.particle_density[i] != m.density) m.mass[i] *= m.particle_density[i] / m.density;
    m.wave_speed = std::max(m.wave_speed, std::sqrt((m.particle_lambda[i] + 2 * m.particle_mu[i]) / m.particle_density[i]));
  }
}

// The mass floor (docs/physics.md (1.18)): m_i = max(m_i, beta * mean of m_j over i's
// neighbours), the means taken over the masses before any is raised (so the result does not
// depend on the particles' order). Volumes, and so forces and every rest state, are unchanged.
void apply_mass_floor(Model& m, double beta) {
  m.mass_floor_raised = 0;
  m.mass_floor_added = 0.0;
  if (beta <= 0) return;
  const std::vector<double> lumped = m.mass;
  for (int i = 0; i < m.particle_count; ++i) {
    const int count = m.neighbor_offset[i + 1] - m.neighbor_offset[i];
    if (count == 0) continue;
    double sum = 0.0;
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) sum += lumped[m.neighbor_index[a]];
    const double floor = beta * sum / count;
    if (lumped[i] < floor) {
      m.mass[i] = floor;
      m.mass_floor_added += floor - lumped[i];
      ++m.mass_floor_raised;
    }
  }
}

// The MLS solid: supports, volumes, moment matrices, gradient weights, hourglass weights.
void build_mls(Model& m, const Scene& scene, const NodeCloud& cloud) {
  const int n = m.particle_count;
  const Points& X = m.rest_position;
  const int k = scene.mls.neighbors;
  if (k >= n)
    throw SceneError(scene.source, "/mls/neighbors",
                     "k = " + std::to_string(k) + " needs more particles than the cloud's " + std::to_string(n));

  // With mls.max_neighbors > k the support grows, one neighbour at a time, until the
  // moment matrix is well conditioned (stretched lattices: the k nearest may be coplanar).
  const int k_max = std::min(n - 1, std::max(k, scene.mls.max_neighbors));
  const Neighborhoods nb = k_nearest_neighbors(X, k_max);
  constexpr double kAdaptiveConditionLimit = 1e4;

  // Support radius h_i = alpha * (mean distance to the k_i neighbours | the k_i-th's distance)
  // (docs/physics.md §1).
  std::vector<double> mean_distance(n);
  std::vector<int> support_count(n, k);
  m.support_radius.resize(n);
  m.min_spacing = INFINITY;
  auto reach_of = [&](int i, int count, double& mean) {
    double sum = 0;
    for (int a = nb.offset[i]; a < nb.offset[i] + count; ++a) sum += std::sqrt(nb.dist2[a]);
    mean = sum / count;
    return scene.mls.support_rule == SupportRule::kth_distance
               ? std::sqrt(nb.dist2[nb.offset[i] + count - 1])  // nearest first
               : mean;
  };
  auto condition_of = [&](int i, int count, double h) {
    Mat3 A = Mat3::Zero();
    for (int a = nb.offset[i]; a < nb.offset[i] + count; ++a) {
      const Vec3 x_ij = X.col(nb.index[a]) - X.col(i);
      A += kernel_weight(nb.dist2[a], h * h) * x_ij * x_ij.transpose();
    }
    const Vec3 ev = Eigen::SelfAdjointEigenSolver<Mat3>(A, Eigen::EigenvaluesOnly).eigenvalues();
    return ev[0] > 0 ? ev[2] / ev[0] : INFINITY;
  };
  for (int i = 0; i < n; ++i) {
    int count = k;
    double reach = reach_of(i, count, mean_distance[i]);
    while (count < k_max && condition_of(i, count, scene.mls.support_factor * reach) > kAdaptiveConditionLimit)
      reach = reach_of(i, ++count, mean_distance[i]);
    support_count[i] = count;
    m.support_radius[i] = scene.mls.support_factor * reach;
    m.min_spacing = std::min(m.min_spacing, std::sqrt(nb.dist2[nb.offset[i]]));
    m.max_spacing = std::max(m.max_spacing, std::sqrt(nb.dist2[nb.offset[i]]));
  }

  // Keep only neighbours inside the support (non-zero weight): the rest contribute nothing.
  m.neighbor_offset.assign(n + 1, 0);
  std::vector<double> weight;
  for (int i = 0; i < n; ++i) {
    const double h2 = m.support_radius[i] * m.support_radius[i];
    for (int a = nb.offset[i]; a < nb.offset[i] + support_count[i]; ++a) {
      const double w = kernel_weight(nb.dist2[a], h2);
      if (w <= 0) continue;
      m.neighbor_index.push_back(nb.index[a]);
      weight.push_back(w);
    }
    m.neighbor_offset[i + 1] = static_cast<int>(m.neighbor_index.size());
  }
  const int nnz = m.neighbor_offset[n];

  // Masses, densities, volumes.
  const double rho = scene.material.density;
  m.mass.resize(n);
  m.volume.resize(n);
  if (scene.mls.volumes == VolumeRule::lattice || scene.mls.volumes == VolumeRule::mesh) {
    // Lattice cell volumes, or the lumped tetrahedra v_i = sum_t |V_t| / 4 (mesh_reader.h).
    const bool lattice = scene.mls.volumes == VolumeRule::lattice;
    const std::vector<double>& volume = lattice ? cloud.lattice_volume : cloud.mesh_volume;
    if (volume.size() != static_cast<size_t>(n))
      throw SceneError(scene.source, "/mls/volumes",
                       lattice ? "lattice volumes need a lattice distribution" : "mesh volumes need a mesh distribution");
    for (int i = 0; i < n; ++i) {
      m.volume[i] = volume[i];
      m.mass[i] = rho * m.volume[i];
    }
  } else {
    // m_i = s rbar_i^3 rho, rho_i = sum_j m_j W(r_ij, h_i) (self included), s such that
    // the mean of rho_i is rho; v_i = m_i / rho_i.
    std::vector<double> density(n);
    for (int i = 0; i < n; ++i) {
      const double h = m.support_radius[i];
      double sum = std::pow(mean_distance[i], 3) * kernel_density(0.0, h);
      for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
        const int j = m.neighbor_index[a];
        sum += std::pow(mean_distance[j], 3) * kernel_density((X.col(j) - X.col(i)).squaredNorm(), h);
      }
      density[i] = rho * sum;  // with s = 1
    }
    const double s = rho / (std::accumulate(density.begin(), density.end(), 0.0) / n);
    for (int i = 0; i < n; ++i) {
      m.mass[i] = s * std::pow(mean_distance[i], 3) * rho;
      m.volume[i] = m.mass[i] / (s * density[i]);
    }
  }
  m.total_volume = std::accumulate(m.volume.begin(), m.volume.end(), 0.0);
  set_particle_materials(m, scene.material,
                         scene.distribution.type == DistributionType::grid ||
                             scene.distribution.type == DistributionType::graded_grid,
                         cloud, scene.source);
  apply_mass_floor(m, scene.mls.mass_floor);

  // Moment matrices and gradient weights (A-6 ... A-9, M-14, M-15):
  // A_i = sum_j w_ij x_ij x_ij^T, d_j = A_i^-1 x_ij w_ij.
  m.gradient_weight.resize(3, nnz);
  m.rest_correction.assign(9 * static_cast<size_t>(n), 0.0);
  std::vector<double> moment_trace(n);
  for (int i = 0; i < n; ++i) {
    Mat3 A = Mat3::Zero();
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const Vec3 x_ij = X.col(m.neighbor_index[a]) - X.col(i);
      A += weight[a] * x_ij * x_ij.transpose();
    }
    moment_trace[i] = A.trace();
    Mat3 A_inv;
    double condition;
    if (regularized_inverse(A, scene.mls.regularization, A_inv, condition)) ++m.regularized_count;
    m.worst_condition = std::max(m.worst_condition, condition);
    Mat3 B = Mat3::Zero();  // sum_j X_ij d_j^T: I unless A_i was regularised
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const Vec3 x_ij = X.col(m.neighbor_index[a]) - X.col(i);
      m.gradient_weight.col(a) = A_inv * x_ij * weight[a];
      B += x_ij * m.gradient_weight.col(a).transpose();
    }
    Eigen::Map<Mat3> correction(&m.rest_correction[9 * static_cast<size_t>(i)]);
    correction = Mat3::Identity() - B;
  }

  // Integration constraint at interior particles (consistent_integration.h): measured
  // always, imposed when the scene asks for it. Interior: off the body's boundary, i.e. not
  // a vertex of a mesh's boundary faces (a body of any shape), else off the box faces.
  std::vector<uint8_t> interior;
  if (!cloud.boundary_triangles.empty()) {
    interior.assign(n, 1);
    for (const auto& t : cloud.boundary_triangles)
      for (int v : t) interior[v] = 0;
  } else {
    interior = particles_on_faces(X, face_x_min | face_x_max | face_y_min | face_y_max | face_bottom | face_top);
    for (auto& flag : interior) flag = !flag;
  }
  if (scene.mls.integration == IntegrationRule::consistent) {
    const IntegrationCorrection c = make_integration_consistent(m, interior);
    m.integration_residual_nodal = c.residual_before;
    m.integration_residual = c.residual_after;
    m.integration_correction = c.relative_change;
  } else {
    m.integration_residual_nodal = m.integration_residual = integration_residual(m, interior);
  }
  // Hourglass control: kappa_i = c * 2 mu * v_i / tr(A_i), per neighbour kappa_i w_ij (1.9); on
  // a cloud refined in-process, only where the support holds a particle the refinement added
  // (the bisected tetrahedra's vertices: the base mesh's own stencils need none).
  if (scene.mls.hourglass > 0) {
    m.hourglass_weight.resize(nnz);
    m.neighbor_rest_offset.resize(3, nnz);
    const int base = cloud.refined_from;
    for (int i = 0; i < n; ++i) {
      bool refined = base == 0 || i >= base;
      for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1] && !refined; ++a) refined = m.neighbor_index[a] >= base;
      const double kappa = refined ? scene.mls.hourglass * 2 * m.particle_mu[i] * m.volume[i] / moment_trace[i] : 0.0;
      for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
        m.hourglass_weight[a] = kappa * weight[a];
        m.neighbor_rest_offset.col(a) = X.col(m.neighbor_index[a]) - X.col(i);
      }
    }
  }
  build_force_blocks(m);  // in particle order (a subcycled model regroups them: core/rate_schedule.h)

}

// The hexahedral FEM reference: the lattice's bricks, lumped masses (rho times the
// nodes' lattice volumes = the row sums of the consistent mass of trilinear bricks).
// Heterogeneous: each element's Lame parameters from its brick's samples (1.16), each node's
// density from its lattice cell.
void build_hex_fem(Model& m, const HexFemSpec& spec, const MaterialSpec& material, const NodeCloud& cloud,
                   const std::string& source) {
  m.solid = SolidKind::hex_fem;
  m.hex = hex_mesh(m.rest_position, cloud.lattice_size, m.lame_lambda, m.lame_mu, spec.formulation,
                   spec.volumetric_integration, material.inclusions.empty() ? nullptr : &material);
  m.volume = cloud.lattice_volume;
  m.mass.resize(m.particle_count);
  for (int i = 0; i < m.particle_count; ++i) m.mass[i] = m.density * m.volume[i];
  set_particle_materials(m, material, /*on_lattice=*/true, cloud, source);  // the bricks are the lattice's cells
  m.total_volume = std::accumulate(m.volume.begin(), m.volume.end(), 0.0);
  m.min_spacing = INFINITY;
  for (const Vec3& size : m.hex.element_size) {
    m.min_spacing = std::min(m.min_spacing, size.minCoeff());
    m.max_spacing = std::max(m.max_spacing, size.maxCoeff());
  }
}

// Fixed particles and the indenter's placement (both models).
void set_boundary_and_indenter(Model& m, const Scene& scene, const NodeCloud& cloud) {
  const int n = m.particle_count;
  const Points& X = m.rest_position;
  // Boundary conditions: the box faces, then the regions (core/boundary.h).
  m.fixed = fixed_particles(scene, cloud);
  m.inverse_mass.resize(n);
  for (int i = 0; i < n; ++i) {
    m.inverse_mass[i] = m.fixed[i] ? 0.0 : 1.0 / m.mass[i];
    m.fixed_count += m.fixed[i];
    if (!m.fixed[i]) m.free_mass += m.mass[i];
  }

  // Indenter: centred over the top face and just touching it unless placed by the scene.
  m.indenter_radius = scene.indenter.radius;
  m.initial_force_command = scene.indenter.force;
  const Vec3 centre_xy = 0.5 * (X.rowwise().minCoeff() + X.rowwise().maxCoeff());
  m.indenter_start = scene.indenter.position_given ? scene.indenter.position
                                                   : Vec3(centre_xy[0], centre_xy[1], 0.0);
  double surface;
  const double first_contact =
      first_touch_height(X, m.indenter_start[0], m.indenter_start[1], m.indenter_radius, surface);
  if (!std::isfinite(first_contact))
    throw SceneError(scene.source, "/indenter/position", "the indenter is not above the body");
  // Indentation is measured from the sphere touching the undeformed surface (docs/physics.md §2);
  // the sphere starts resting on the particles, which may already be below that by the
  // strain-free sinking between them.
  m.touch_height = surface + m.indenter_radius;
  // With a surface: the first contact of the sphere with its triangles (2.16); a flat top
  // gives the same Z_top + R.
  const double surface_contact = sphere_first_contact_height(m.rest_position, m.surface_triangles,
                                                             m.indenter_start[0], m.indenter_start[1],
                                                             m.indenter_radius);
  if (std::isfinite(surface_contact)) m.touch_height = surface_contact;
  if (!scene.indenter.position_given) m.indenter_start[2] = first_contact;
  // The tool's workspace.
  const Vec3 margin = Vec3::Constant(2 * m.indenter_radius);
  const Vec3 body_min = X.rowwise().minCoeff() - margin, body_max = X.rowwise().maxCoeff() + margin;
  for (int a = 0; a < 3; ++a) {
    const double lo = scene.indenter.workspace_min[a], hi = scene.indenter.workspace_max[a];
    // A derived corner also takes in the start, so a scene that parks the tool away keeps it there.
    m.tool_workspace_min[a] = std::isfinite(lo) ? lo : std::min(body_min[a], m.indenter_start[a]);
    m.tool_workspace_max[a] = std::isfinite(hi) ? hi : std::max(body_max[a], m.indenter_start[a]);
  }
  if (!(m.tool_workspace_max.array() > m.tool_workspace_min.array()).all())
    throw SceneError(scene.source, "/indenter/workspace_max",
                     "the tool's workspace is empty (workspace_max must exceed workspace_min, or the corner derived "
                     "from the body, in every component)");
  if ((m.indenter_start.array() < m.tool_workspace_min.array()).any() ||
      (m.indenter_start.array() > m.tool_workspace_max.array()).any())
    throw SceneError(scene.source, "/indenter/workspace_min",
                     "the indenter starts outside its workspace (the box of workspace_min and workspace_max)");
  if (m.indenter_start[2] < first_contact - 1e-12)
    throw SceneError(scene.source, "/indenter/position",
                     "the indenter starts inside the body (its centre must be at z >= " +
                         std::to_string(first_contact) + ")");

}

}  // namespace

Model build_model(const Scene& scene) { return build_model(scene, make_node_cloud(scene)); }

Model build_model(const Scene& scene, const NodeCloud& cloud) {
  Model m;
  m.name = scene.name;
  m.source = scene.source;
  m.distribution = scene.distribution.type;
  m.particle_count = static_cast<int>(cloud.positions.cols());
  m.rest_position = cloud.positions;
  m.mesh_tetrahedra = cloud.mesh_tetrahedra;
  m.mesh_unused_nodes = cloud.mesh_unused_nodes;
  m.surface_triangles = cloud_surface(cloud);
  // A mesh body without a box: its own volume (the sum of its tetrahedra's).
  m.box_volume = scene.box_given ? (scene.box.max - scene.box.min).prod()
                                 : std::accumulate(cloud.mesh_volume.begin(), cloud.mesh_volume.end(), 0.0);
  set_material(m, scene.material);
  switch (scene.model) {
    case SolidKind::mls: build_mls(m, scene, cloud); break;
    case SolidKind::hex_fem: build_hex_fem(m, scene.hex_fem, scene.material, cloud, scene.source); break;
  }
  set_boundary_and_indenter(m, scene, cloud);
  spdlog::debug("model {}: {} particles, {} fixed, {} regularised (worst cond {:.3g}), volume {:.4g} of box {:.4g}",
                to_string(scene.model), m.particle_count, m.fixed_count, m.regularized_count, m.worst_condition,
                m.total_volume, m.box_volume);
  if (scene.distribution.type == DistributionType::mesh)
    spdlog::debug("mesh {}: {} tetrahedra, {} unused nodes dropped", scene.distribution.mesh_file.string(),
                  m.mesh_tetrahedra, m.mesh_unused_nodes);
  // A cloud the spacing estimate misjudges (a refined mesh's close pairs): the model's own
  // highest frequency decides, computed only then, and only for refined meshes, where it was
  // measured to hold under load (time_step.h).
  const Options opt = options_of(scene);
  if (scene.distribution.type == DistributionType::mesh && scene.distribution.refine.enabled() &&
      !opt.integrator.allow_unstable_dt && opt.integrator.dt > stable_time_step(m, opt.integrator.type))
    m.spectral_time_step = spectral_time_step(m, opt.integrator.type);
  if (scene.integrator.max_interval > 1) {
    if (scene.model != SolidKind::mls)
      throw SceneError(scene.source, "/integrator/max_interval",
                       "subcycling applies to the MLS model only (this scene's is " + std::string(to_string(scene.model)) + ")");
    if (scene.integrator.type != IntegratorType::symplectic_euler)
      throw SceneError(scene.source, "/integrator/max_interval",
                       "subcycling applies to the symplectic_euler integrator only (this scene's is " +
                           std::string(to_string(scene.integrator.type)) + ")");
    build_rate_schedule(m, scene.integrator.max_interval, opt.integrator.dt);
  }
  check_options(m, opt);
  return m;
}

}  // namespace palpate
