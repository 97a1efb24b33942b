#include "core/node_cloud.h"

#include "core/mesh_reader.h"
#include "core/mesh_refinement.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>

namespace palpate {

namespace {

// The 1-D cell length owned by each node of an axis (half of each adjacent
// interval), so that the product of three of them is the node's share of the box.
std::vector<double> axis_shares(const std::vector<double>& coord) {
  const size_t count = coord.size();
  std::vector<double> share(count, 0.0);
  for (size_t a = 0; a + 1 < count; ++a) {
    const double half = 0.5 * (coord[a + 1] - coord[a]);
    share[a] += half;
    share[a + 1] += half;
  }
  return share;
}

std::vector<double> uniform_axis(double lo, double hi, int count) {
  std::vector<double> coord(count);
  const double h = (hi - lo) / (count - 1);
  for (int a = 0; a < count; ++a) coord[a] = (a == count - 1) ? hi : lo + a * h;
  return coord;
}

// Node lattice built from three axis coordinate lists; volumes from the axis shares.
NodeCloud tensor_lattice(const std::vector<double> (&coord)[3]) {
  std::vector<double> share[3];
  Eigen::Vector3i per_axis;
  for (int c = 0; c < 3; ++c) {
    share[c] = axis_shares(coord[c]);
    per_axis[c] = static_cast<int>(coord[c].size());
  }
  NodeCloud cloud;
  const int n = per_axis.prod();
  cloud.positions.resize(3, n);
  cloud.lattice_volume.resize(n);
  cloud.lattice_size = per_axis;
  int i = 0;
  for (int c = 0; c < per_axis[2]; ++c)
    for (int b = 0; b < per_axis[1]; ++b)
      for (int a = 0; a < per_axis[0]; ++a, ++i) {
        cloud.positions.col(i) = Vec3(coord[0][a], coord[1][b], coord[2][c]);
        cloud.lattice_volume[i] = share[0][a] * share[1][b] * share[2][c];
      }
  return cloud;
}

}  // namespace

// What the model keeps of a mesh.
NodeCloud mesh_cloud(const TetMesh& mesh) {
  NodeCloud cloud;
  cloud.positions = mesh.positions;
  cloud.mesh_volume = mesh.nodal_volume;
  cloud.mesh_tetrahedra = static_cast<int64_t>(mesh.tetrahedra.size());
  cloud.mesh_unused_nodes = mesh.unused_nodes;
  cloud.tetrahedra = mesh.tetrahedra;
  cloud.tetrahedron_region = mesh.tetrahedron_region;
  for (const SurfaceGroup& g : mesh.surface_groups) cloud.surface_node_sets.push_back({g.name, g.tag, g.nodes});
  for (const PhysicalName& p : mesh.physical_names)
    if (p.dimension == 3) cloud.volume_groups.push_back({p.name, p.tag});
  cloud.boundary_triangles = mesh.boundary_faces;
  return cloud;
}

Eigen::Vector3i nodes_per_axis(const BoxSpec& box, double spacing) {
  Eigen::Vector3i n;
  for (int c = 0; c < 3; ++c) n[c] = static_cast<int>(std::lround((box.max[c] - box.min[c]) / spacing)) + 1;
  return n;
}

double geometric_ratio(double first, double length, int intervals) {
  auto sum = [&](double r) {
    return std::abs(r - 1.0) < 1e-12 ? first * intervals : first * (std::pow(r, intervals) - 1.0) / (r - 1.0);
  };
  double lo = std::log(1e-3), hi = std::log(1e3);
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    (sum(std::exp(mid)) < length ? lo : hi) = mid;
  }
  return std::exp(0.5 * (lo + hi));
}

NodeCloud grid_nodes(const BoxSpec& box, const Eigen::Vector3i& per_axis) {
  std::vector<double> coord[3];
  for (int c = 0; c < 3; ++c) {
    if (per_axis[c] < 2) throw std::invalid_argument("grid_nodes: at least 2 nodes per axis");
    coord[c] = uniform_axis(box.min[c], box.max[c], per_axis[c]);
  }
  return tensor_lattice(coord);
}

std::vector<double> graded_axis(double lo, double hi, double focus, int count, double first_spacing) {
  if (count < 2) throw std::invalid_argument("graded lattice: at least 2 nodes per axis");
  if (!(focus >= lo && focus <= hi)) throw std::invalid_argument("graded lattice: the focus is outside the box");
  const int intervals = count - 1;
  const double below = focus - lo, above = hi - focus;
  // Intervals on each side of the focus in proportion to its length (at least one on a side
  // of positive length); a focus on a face grades one-sidedly.
  int n_below = below <= 0 ? 0 : above <= 0 ? intervals
                                            : static_cast<int>(std::lround(intervals * below / (below + above)));
  if (below > 0 && above > 0) n_below = std::clamp(n_below, 1, intervals - 1);
  if (below > 0 && above > 0 && intervals < 2)
    throw std::invalid_argument("graded lattice: a focus inside the box needs at least 3 nodes per axis");
  const int n_above = intervals - n_below;
  std::vector<double> coord(count);
  coord[n_below] = focus;
  for (int side = 0; side < 2; ++side) {
    const int n = side == 0 ? n_below : n_above;
    const double length = side == 0 ? below : above;
    if (n == 0) continue;
    if (!(first_spacing < length || n == 1))
      throw std::invalid_argument("graded lattice: the first spacing " + std::to_string(first_spacing) +
                                  " m does not fit a side of " + std::to_string(length) + " m");
    const double r = n == 1 ? 1.0 : geometric_ratio(first_spacing, length, n);
    double h = n == 1 ? length : first_spacing, x = focus;
    for (int k = 1; k <= n; ++k, h *= r) {
      x += side == 0 ? -h : h;
      coord[side == 0 ? n_below - k : n_below + k] = x;
    }
    coord[side == 0 ? 0 : count - 1] = side == 0 ? lo : hi;  // exact ends
  }
  return coord;
}

NodeCloud graded_grid_nodes(const BoxSpec& box, const Eigen::Vector3i& per_axis, const Vec3& focus,
                            double first_spacing) {
  std::vector<double> coord[3];
  for (int c = 0; c < 3; ++c) coord[c] = graded_axis(box.min[c], box.max[c], focus[c], per_axis[c], first_spacing);
  return tensor_lattice(coord);
}

Vec3 graded_focus(const Scene& scene) {
  if (scene.distribution.focus_given) return scene.distribution.focus;
  const Vec3 centre = 0.5 * (scene.box.min + scene.box.max);
  const bool placed = scene.indenter.position_given;
  return Vec3(placed ? scene.indenter.position[0] : centre[0], placed ? scene.indenter.position[1] : centre[1],
              scene.box.max[2]);
}

NodeCloud jittered_grid_nodes(const BoxSpec& box, const Eigen::Vector3i& per_axis, double jitter,
                              uint64_t seed) {
  NodeCloud cloud = grid_nodes(box, per_axis);
  std::mt19937_64 rng(seed);
  // Uniform in [-1, 1) from the raw 64-bit output: identical on every platform.
  auto uniform = [&rng] { return static_cast<double>(rng() >> 11) * 0x1.0p-52 - 1.0; };
  for (int i = 0; i < cloud.positions.cols(); ++i) {
    for (int c = 0; c < 3; ++c) {
      const double h = (box.max[c] - box.min[c]) / (per_axis[c] - 1);
      const double r = uniform();  // drawn for every component so the sequence is fixed
      double& x = cloud.positions(c, i);
      const bool on_face = std::abs(x - box.min[c]) < 1e-12 * h || std::abs(x - box.max[c]) < 1e-12 * h;
      if (!on_face) x += jitter * h * r;
    }
  }
  // The lattice volumes remain a fair estimate of a jittered node's share.
  return cloud;
}

NodeCloud load_node_list(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw std::runtime_error(file.string() + ": cannot open node list");
  std::vector<Vec3> nodes;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream fields(line);
    Vec3 p;
    std::string extra;
    if (!(fields >> p[0] >> p[1] >> p[2]) || (fields >> extra) || !p.allFinite())
      throw std::runtime_error(file.string() + ":" + std::to_string(line_number) +
                               ": expected three finite numbers \"x y z\", got \"" + line + "\"");
    nodes.push_back(p);
  }
  if (nodes.size() < 8)
    throw std::runtime_error(file.string() + ": a node list needs at least 8 nodes, found " +
                             std::to_string(nodes.size()));
  NodeCloud cloud;
  cloud.positions.resize(3, static_cast<Eigen::Index>(nodes.size()));
  for (size_t i = 0; i < nodes.size(); ++i) cloud.positions.col(static_cast<Eigen::Index>(i)) = nodes[i];
  return cloud;
}

NodeCloud mesh_node_cloud(const Scene& scene) {
  const TetMesh mesh = read_mesh(scene.distribution.mesh_file);
  const std::string field = "/body/distribution/file";
  const BoxSpec& box = scene.box;
  const Vec3 lo = mesh.positions.rowwise().minCoeff(), hi = mesh.positions.rowwise().maxCoeff();
  const double tolerance = 1e-6 * (box.max - box.min).norm();
  auto text = [](const Vec3& v) {
    std::ostringstream s;
    s.precision(9);
    s << '[' << v[0] << ", " << v[1] << ", " << v[2] << ']';
    return s.str();
  };
  const std::string name = scene.distribution.mesh_file.string();
  if (!scene.box_given) return refined_mesh_cloud(scene, mesh, tool_centre(scene, mesh));  // a body of any shape
  if ((lo - box.min).cwiseAbs().maxCoeff() > tolerance || (hi - box.max).cwiseAbs().maxCoeff() > tolerance)
    throw SceneError(scene.source, field,
                     "the mesh " + name + " spans " + text(lo) + " ... " + text(hi) + ", not /body/box " +
                         text(box.min) + " ... " + text(box.max) + ": the mesh must fill the box");
  const double box_volume = (box.max - box.min).prod();
  if (std::abs(mesh.total_volume - box_volume) > 1e-6 * box_volume) {
    std::ostringstream s;
    s.precision(9);
    s << "the tetrahedra of " << name << " hold " << mesh.total_volume << " m^3, the box " << box_volume
      << " m^3 (a hole, an overlap or another shape): the mesh must fill /body/box";
    throw SceneError(scene.source, field, s.str());
  }
  return refined_mesh_cloud(scene, mesh, tool_centre(scene, mesh));
}

Vec3 tool_centre(const Scene& scene, const TetMesh& mesh) {
  if (scene.indenter.position_given) return scene.indenter.position;
  // build_model's default: over the centre of the body's bounding box, above its top.
  const Vec3 lo = mesh.positions.rowwise().minCoeff(), hi = mesh.positions.rowwise().maxCoeff();
  return Vec3(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] + scene.indenter.radius);
}

Vec3 refinement_focus(const Scene& scene, const TetMesh& base, const Vec3& tool) {
  return scene.distribution.focus_given ? scene.distribution.focus : nearest_boundary_point(base, tool);
}

NodeCloud refined_mesh_cloud(const Scene& scene, const TetMesh& base, const Vec3& tool) {
  const DistributionSpec& d = scene.distribution;
  if (!d.refine.enabled()) return mesh_cloud(base);
  MeshRefinement spec;
  spec.focus = refinement_focus(scene, base, tool);
  spec.focus_size = d.refine.size;
  spec.growth = d.refine.growth;
  if (d.refine.max_size > 0) spec.max_size = d.refine.max_size;
  try {
    NodeCloud cloud = mesh_cloud(refine_mesh(base, spec));
    cloud.refined_from = static_cast<int>(base.positions.cols());
    return cloud;
  } catch (const std::invalid_argument& e) {
    throw SceneError(scene.source, "/body/distribution/refine/size", e.what());
  }
}

NodeCloud make_node_cloud(const Scene& scene) {
  const DistributionSpec& d = scene.distribution;
  const Eigen::Vector3i per_axis =
      d.spacing > 0 ? nodes_per_axis(scene.box, d.spacing) : Eigen::Vector3i::Constant(d.per_edge);
  switch (d.type) {
    case DistributionType::grid: return grid_nodes(scene.box, per_axis);
    case DistributionType::jittered_grid: return jittered_grid_nodes(scene.box, per_axis, d.jitter, d.seed);
    case DistributionType::graded_grid:
      return graded_grid_nodes(scene.box, per_axis, graded_focus(scene), d.first_spacing);
    case DistributionType::node_file: return load_node_list(d.node_file);
    case DistributionType::mesh: return mesh_node_cloud(scene);
  }
  throw std::logic_error("make_node_cloud: unknown distribution");
}

}  // namespace palpate
