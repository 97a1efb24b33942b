// The deformation carried from one cloud to another of the same body (cloud_transfer.h).
#include "core/cloud_transfer.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace palpate {

namespace {

// A key of a point's exact coordinates (the same double triple gives the same key).
struct PointKey {
  uint64_t bits[3];
  bool operator==(const PointKey& o) const { return std::memcmp(bits, o.bits, sizeof bits) == 0; }
};
struct PointKeyHash {
  size_t operator()(const PointKey& k) const {
    return std::hash<uint64_t>()(k.bits[0] * 0x9E3779B97F4A7C15ull ^ k.bits[1] * 0xC2B2AE3D27D4EB4Full ^ k.bits[2]);
  }
};
PointKey key_of(const Vec3& p) {
  PointKey k;
  std::memcpy(k.bits, p.data(), sizeof k.bits);
  return k;
}

// Old tetrahedra binned by their bounding boxes on a uniform grid of about one cell each.
class TetrahedronGrid {
 public:
  TetrahedronGrid(const Points& X, const std::vector<std::array<int, 4>>& tets) : X_(X), tets_(tets) {
    lo_ = X.rowwise().minCoeff();
    const Vec3 hi = X.rowwise().maxCoeff();
    const double volume = std::max((hi - lo_).prod(), 1e-300);
    cell_ = std::cbrt(volume / std::max<size_t>(tets.size(), 1));
    for (int a = 0; a < 3; ++a) count_[a] = std::max(1, static_cast<int>(std::ceil((hi[a] - lo_[a]) / cell_)));
    start_.assign(static_cast<size_t>(count_[0]) * count_[1] * count_[2] + 1, 0);
    // Two passes (count, fill): a CSR of the cells' tetrahedra.
    for (int pass = 0; pass < 2; ++pass) {
      std::vector<int> fill;
      if (pass == 1) {
        for (size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
        members_.resize(start_.back());
        fill.assign(start_.begin(), start_.end() - 1);
      }
      for (int t = 0; t < static_cast<int>(tets.size()); ++t) {
        Vec3 tlo = X.col(tets[t][0]), thi = tlo;
        for (int v : tets[t]) {
          tlo = tlo.cwiseMin(X.col(v));
          thi = thi.cwiseMax(X.col(v));
        }
        const Eigen::Vector3i a = cell_of(tlo), b = cell_of(thi);
        for (int i = a[0]; i <= b[0]; ++i)
          for (int j = a[1]; j <= b[1]; ++j)
            for (int k = a[2]; k <= b[2]; ++k) {
              const size_t c = index(i, j, k);
              if (pass == 0)
                ++start_[c + 1];
              else
                members_[fill[c]++] = t;
            }
      }
    }
  }

  // The tetrahedron holding p (the largest smallest barycentric coordinate among those of its
  // cell) and its coordinates; false when none comes within `tolerance` of holding it.
  bool locate(const Vec3& p, double tolerance, int& tet, std::array<double, 4>& lambda, double& least) const {
    const Eigen::Vector3i c = cell_of(p);
    const size_t cell = index(c[0], c[1], c[2]);
    least = -INFINITY;
    for (int m = start_[cell]; m < start_[cell + 1]; ++m) {
      const auto& t = tets_[members_[m]];
      const Vec3 a = X_.col(t[0]);
      Mat3 E;
      E << X_.col(t[1]) - a, X_.col(t[2]) - a, X_.col(t[3]) - a;
      const Vec3 l = E.inverse() * (p - a);
      const std::array<double, 4> candidate{1.0 - l.sum(), l[0], l[1], l[2]};
      const double smallest = *std::min_element(candidate.begin(), candidate.end());
      if (smallest > least) {
        least = smallest;
        tet = members_[m];
        lambda = candidate;
      }
    }
    return least >= -tolerance;
  }

 private:
  Eigen::Vector3i cell_of(const Vec3& p) const {
    Eigen::Vector3i c;
    for (int a = 0; a < 3; ++a)
      c[a] = std::clamp(static_cast<int>(std::floor((p[a] - lo_[a]) / cell_)), 0, count_[a] - 1);
    return c;
  }
  size_t index(int i, int j, int k) const {
    return (static_cast<size_t>(k) * count_[1] + j) * count_[0] + i;
  }

  const Points& X_;
  const std::vector<std::array<int, 4>>& tets_;
  Vec3 lo_;
  double cell_ = 1.0;
  int count_[3] = {1, 1, 1};
  std::vector<int> start_, members_;
};

}  // namespace

namespace {

// Rows of weights from the cloud (X, tets) to the points P: exact copies where a point is a
// vertex, else barycentric coordinates in the tetrahedron holding it.
void interpolation_rows(const Points& X, const std::vector<std::array<int, 4>>& tets, const Points& P,
                        const char* what, std::vector<int>& offset, std::vector<int>& source,
                        std::vector<double>& weight, int& exact, double& worst_outside) {
  if (tets.empty()) throw std::invalid_argument(std::string("cloud transfer: the ") + what + " cloud has no tetrahedra");
  offset.assign(P.cols() + 1, 0);
  std::unordered_map<PointKey, int, PointKeyHash> vertex_at;
  vertex_at.reserve(X.cols());
  for (int i = 0; i < X.cols(); ++i) vertex_at.emplace(key_of(X.col(i)), i);
  const TetrahedronGrid grid(X, tets);
  // How far outside the other cloud's tetrahedra a point may lie, in barycentric coordinates
  // (then extrapolated linearly from the nearest tetrahedron: exact for an affine field).
  // Beyond round-off it is a curved body's surface: its new surface vertices lie on the
  // curved surface (7.1a), outside the other refinement's coarser facets by up to their sag
  // h^2 / (8 R_b), a coordinate of about -h / (8 R_b) (-0.01 for the dome's 3 mm facets).
  // Further out, the point is not of the same body.
  constexpr double kTolerance = 0.05;
  for (int i = 0; i < P.cols(); ++i) {
    const Vec3 p = P.col(i);
    if (const auto it = vertex_at.find(key_of(p)); it != vertex_at.end()) {
      source.push_back(it->second);
      weight.push_back(1.0);
      ++exact;
    } else {
      int tet = -1;
      std::array<double, 4> lambda{};
      double least = 0;
      if (!grid.locate(p, kTolerance, tet, lambda, least))
        throw std::invalid_argument("cloud transfer: particle " + std::to_string(i) + " lies outside the " + what +
                                    " cloud's tetrahedra (not the same body)");
      worst_outside = std::min(worst_outside, least);
      for (int a = 0; a < 4; ++a) {
        if (lambda[a] == 0.0) continue;
        source.push_back(tets[tet][a]);
        weight.push_back(lambda[a]);
      }
    }
    offset[i + 1] = static_cast<int>(source.size());
  }
}

}  // namespace

CloudTransfer make_cloud_transfer(const Points& old_rest, const std::vector<std::array<int, 4>>& old_tetrahedra,
                                  const Points& new_rest, const std::vector<std::array<int, 4>>& new_tetrahedra) {
  CloudTransfer out;
  out.new_count = static_cast<int>(new_rest.cols());
  interpolation_rows(old_rest, old_tetrahedra, new_rest, "old", out.offset, out.source, out.weight, out.exact,
                     out.worst_outside);
  int back_exact = 0;
  interpolation_rows(new_rest, new_tetrahedra, old_rest, "new", out.back_offset, out.back_source, out.back_weight,
                     back_exact, out.worst_outside);
  out.new_slot.assign(out.new_count, -1);
  return out;
}

void transfer_state(const CloudTransfer& transfer, const Model& from_model, const CarriedState& from,
                    const Model& to_model, State& to) {
  if (transfer.new_count != to_model.particle_count || to.position.cols() != to_model.particle_count ||
      transfer.back_offset.size() != static_cast<size_t>(from_model.particle_count) + 1)
    throw std::invalid_argument("transfer_state: the transfer or the state is not of the new model");
  const Points& X_old = from_model.rest_position;
  for (int i = 0; i < transfer.new_count; ++i) {
    Vec3 u = Vec3::Zero(), v = Vec3::Zero();
    for (int a = transfer.offset[i]; a < transfer.offset[i + 1]; ++a) {
      const int s = transfer.source[a];
      u += transfer.weight[a] * (from.position.col(s) - X_old.col(s));  // (7.2)
      v += transfer.weight[a] * from.velocity.col(s);
    }
    // A fixed particle of the new model stays where its boundary condition holds it.
    to.position.col(i) = to_model.fixed[i] ? Vec3(to_model.rest_position.col(i)) : Vec3(to_model.rest_position.col(i) + u);
    to.velocity.col(i) = to_model.fixed[i] ? Vec3::Zero() : v;
  }
  copy_tool(from, to);
  to.indenter_contact_force = from.indenter_contact_force;
  to.time = from.time;
  to.tick = from.tick;
  std::fill(to.elastic_update_tick.begin(), to.elastic_update_tick.end(), from.tick - 1);
  to.health = from.health;
  to.health.inversion_cursor = 0;

  // The contact forces as point forces at the old particles' reference positions.
  std::vector<int>& slot = transfer.new_slot;
  to.contact_index.clear();
  to.contact_normal_force.clear();
  for (size_t c = 0; c < from.contact_index.size(); ++c) {
    const int s = from.contact_index[c];
    for (int a = transfer.back_offset[s]; a < transfer.back_offset[s + 1]; ++a) {
      const int i = transfer.back_source[a];
      if (to_model.fixed[i]) continue;
      if (slot[i] < 0) {
        slot[i] = static_cast<int>(to.contact_index.size());
        to.contact_index.push_back(i);
        to.contact_force.col(slot[i]).setZero();
      }
      to.contact_force.col(slot[i]) += transfer.back_weight[a] * from.contact_force.col(static_cast<Eigen::Index>(c));
    }
  }
  for (size_t k = 0; k < to.contact_index.size(); ++k) {
    const int i = to.contact_index[k];
    slot[i] = -1;
    // The multiplier along the outward direction from the tool's centre (contact.cpp's).
    const Vec3 n = (to.position.col(i) - to.indenter_center).normalized();
    to.contact_normal_force.push_back(std::max(0.0, to.contact_force.col(static_cast<Eigen::Index>(k)).dot(n)));
  }
}

}  // namespace palpate
