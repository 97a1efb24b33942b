#include "core/node_cloud.h"

#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>

namespace palpate {

namespace {

// Per-axis lattice coordinates and the 1-D cell length owned by each node
// (half a spacing at the two ends), so that the product of three of them is the
// node's share of the box volume.
void axis_lattice(double lo, double hi, int count, std::vector<double>& coord,
                  std::vector<double>& share) {
  coord.resize(count);
  share.resize(count);
  const double h = (hi - lo) / (count - 1);
  for (int a = 0; a < count; ++a) {
    coord[a] = (a == count - 1) ? hi : lo + a * h;
    share[a] = (a == 0 || a == count - 1) ? 0.5 * h : h;
  }
}

}  // namespace

Eigen::Vector3i nodes_per_axis(const BoxSpec& box, double spacing) {
  Eigen::Vector3i n;
  for (int c = 0; c < 3; ++c) n[c] = static_cast<int>(std::lround((box.max[c] - box.min[c]) / spacing)) + 1;
  return n;
}

NodeCloud grid_nodes(const BoxSpec& box, const Eigen::Vector3i& per_axis) {
  std::vector<double> coord[3], share[3];
  for (int c = 0; c < 3; ++c) {
    if (per_axis[c] < 2) throw std::invalid_argument("grid_nodes: at least 2 nodes per axis");
    axis_lattice(box.min[c], box.max[c], per_axis[c], coord[c], share[c]);
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

NodeCloud make_node_cloud(const Scene& scene) {
  const DistributionSpec& d = scene.distribution;
  const Eigen::Vector3i per_axis =
      d.spacing > 0 ? nodes_per_axis(scene.box, d.spacing) : Eigen::Vector3i::Constant(d.per_edge);
  switch (d.type) {
    case DistributionType::grid: return grid_nodes(scene.box, per_axis);
    case DistributionType::jittered_grid: return jittered_grid_nodes(scene.box, per_axis, d.jitter, d.seed);
    case DistributionType::node_file: return load_node_list(d.node_file);
  }
  throw std::logic_error("make_node_cloud: unknown distribution");
}

}  // namespace palpate
