#include "analysis/tet_reference.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>

#include "analysis/reference.h"
#include "core/boundary.h"
#include "core/material_field.h"
#include "core/node_cloud.h"
#include "core/surface.h"

namespace palpate {

void tetrahedra_stiffness(const Points& X, const std::vector<std::array<int, 4>>& tetrahedra,
                          const std::vector<double>& lambda, const std::vector<double>& mu,
                          std::vector<Eigen::Triplet<double>>& lower) {
  lower.reserve(lower.size() + tetrahedra.size() * 78);
  for (size_t t = 0; t < tetrahedra.size(); ++t) {
    const std::array<int, 4>& n = tetrahedra[t];
    // Shape-function gradients (5.9): with J = [x_b - x_a, x_c - x_a, x_d - x_a], the gradients
    // of N_b, N_c, N_d are the rows of J^-1 and grad N_a = -(their sum); V = det J / 6.
    Mat3 J;
    for (int k = 0; k < 3; ++k) J.col(k) = X.col(n[k + 1]) - X.col(n[0]);
    const double volume = J.determinant() / 6.0;
    if (!(volume > 0.0)) throw std::invalid_argument("tetrahedra_stiffness: tetrahedron " + std::to_string(t) +
                                                     " has no positive volume");
    const Mat3 Jinv = J.inverse();
    Eigen::Matrix<double, 3, 4> G;  // column a: grad N_a
    G.rightCols<3>() = Jinv.transpose();
    G.col(0) = -G.rightCols<3>().rowwise().sum();
    // K_ab = V (lambda g_a g_b^T + mu g_b g_a^T + mu (g_a . g_b) I), the blocks of V B^T D B.
    const double l = lambda[t] * volume, m = mu[t] * volume;
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        const Mat3 K = l * G.col(a) * G.col(b).transpose() + m * G.col(b) * G.col(a).transpose() +
                       m * G.col(a).dot(G.col(b)) * Mat3::Identity();
        for (int c = 0; c < 3; ++c)
          for (int d = 0; d < 3; ++d) {
            const int row = 3 * n[a] + c, col = 3 * n[b] + d;
            if (row >= col) lower.emplace_back(row, col, K(c, d));
          }
      }
  }
}

LinearBody tet_body(const Scene& scene_in, const std::filesystem::path& file) {
  Scene scene = scene_in;
  if (!file.empty()) {
    scene.distribution.type = DistributionType::mesh;
    scene.distribution.mesh_file = file;
  }
  if (scene.distribution.type != DistributionType::mesh)
    throw std::invalid_argument("the tetrahedral reference needs a mesh body (body.distribution.type \"mesh\")");
  const NodeCloud cloud = mesh_node_cloud(scene);
  const Points& X = cloud.positions;
  const int n = static_cast<int>(X.cols());
  LinearBody body;
  body.rest_position = X;
  body.fixed = fixed_particles(scene, cloud);

  // Each tetrahedron: the last inclusion that contains it (its centroid; a group: its region), else the matrix.
  const MaterialSpec& material = scene.material;
  std::vector<int64_t> group_tag(material.inclusions.size(), -1);
  for (size_t k = 0; k < material.inclusions.size(); ++k)
    if (material.inclusions[k].shape == InclusionShape::group)
      group_tag[k] = group_inclusion_tag(material, k, cloud, scene.source);
  const size_t T = cloud.tetrahedra.size();
  std::vector<double> lambda(T), mu(T);
  for (size_t t = 0; t < T; ++t) {
    Vec3 centroid = Vec3::Zero();
    for (int a : cloud.tetrahedra[t]) centroid += X.col(a) / 4.0;
    LameParameters p = lame_parameters(material.young_modulus, material.poisson_ratio);
    for (size_t k = 0; k < material.inclusions.size(); ++k) {
      const InclusionSpec& inc = material.inclusions[k];
      const bool inside = inc.shape == InclusionShape::group ? cloud.tetrahedron_region[t] == group_tag[k]
                                                             : inc.contains(centroid);
      if (inside) p = lame_parameters(inc.young_modulus, inc.poisson_ratio);
    }
    lambda[t] = p.lambda;
    mu[t] = p.mu;
  }
  tetrahedra_stiffness(X, cloud.tetrahedra, lambda, mu, body.stiffness_lower);

  // The sphere over the site: first touch with the mesh's boundary faces, candidates the free
  // boundary nodes within its radius.
  // The site as build_model places the tool: the scene's position, else over the centre of the
  // body's bounding box (the top face's centre for a box).
  const Eigen::Vector2d site = scene.indenter.position_given
                                   ? Eigen::Vector2d(scene.indenter.position.head<2>())
                                   : Eigen::Vector2d(0.5 * (X.rowwise().minCoeff() + X.rowwise().maxCoeff()).head<2>());
  const double R = scene.indenter.radius;
  body.indenter_radius = R;
  body.site_x = site[0];
  body.site_y = site[1];
  const SurfaceTriangles surface = cloud_surface(cloud);
  body.touch_height = sphere_first_contact_height(X, surface, site[0], site[1], R);
  if (!std::isfinite(body.touch_height))
    throw std::invalid_argument("the sphere over the site (" + std::to_string(site[0]) + ", " +
                                std::to_string(site[1]) + ") misses the body of " +
                                scene.distribution.mesh_file.string());
  std::vector<uint8_t> on_surface(n, 0);
  for (Eigen::Index t = 0; t < surface.cols(); ++t)
    for (int k = 0; k < 3; ++k) on_surface[surface(k, t)] = 1;
  for (int i = 0; i < n; ++i) {
    const double dx = X(0, i) - site[0], dy = X(1, i) - site[1];
    if (on_surface[i] && !body.fixed[i] && dx * dx + dy * dy < R * R) body.candidate.push_back(i);
  }
  if (body.candidate.empty())
    throw std::invalid_argument("no free boundary node of " + scene.distribution.mesh_file.string() +
                                " lies under the sphere");
  return body;
}

Reference tet_mesh_reference(const Scene& scene, const std::vector<double>& forces,
                             const std::vector<TetMeshLevel>& levels,
                             const std::function<void(const std::string&)>& progress) {
  if (levels.size() < 3) throw std::invalid_argument("the reference needs at least three meshes");
  for (size_t k = 1; k < levels.size(); ++k)
    if (!(levels[k].spacing < levels[k - 1].spacing))
      throw std::invalid_argument("the meshes must be given coarse to fine: " + levels[k].file.string() +
                                  " is not finer than " + levels[k - 1].file.string());
  Reference ref;
  ref.forces = forces;
  ref.key = reference_key(scene);
  for (const TetMeshLevel& mesh : levels) {
    const auto start = std::chrono::steady_clock::now();
    LinearBody body = tet_body(scene, mesh.file);
    ReferenceLevel level;
    level.nodes = static_cast<int>(body.rest_position.cols());
    level.first_spacing = mesh.spacing;
    LinearStaticContact solver(std::move(body));
    for (double F : forces) {
      const StaticSolution sol = solver.solve(F);
      if (!sol.converged)
        throw std::runtime_error(mesh.file.string() + ", F = " + std::to_string(F) + " N: " + sol.message);
      level.indentation.push_back(sol.indentation);
    }
    level.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (progress) {
      std::ostringstream o;
      o << "reference mesh " << mesh.file.string() << " (" << level.nodes << " nodes, spacing " << mesh.spacing
        << " m, " << solver.columns_computed() << " compliance columns): " << level.seconds << " s";
      progress(o.str());
    }
    ref.levels.push_back(std::move(level));
  }
  extrapolate_indentation(ref);
  return ref;
}

}  // namespace palpate
