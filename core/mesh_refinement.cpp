// Longest-edge (LEPP) bisection of a tetrahedral mesh toward a focus (mesh_refinement.h).
#include "core/mesh_refinement.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace palpate {

namespace {

using EdgeKey = uint64_t;  // (smaller index << 32) | larger index

EdgeKey edge_key(int a, int b) {
  if (a > b) std::swap(a, b);
  return (static_cast<uint64_t>(a) << 32) | static_cast<uint32_t>(b);
}
int edge_first(EdgeKey e) { return static_cast<int>(e >> 32); }
int edge_second(EdgeKey e) { return static_cast<int>(e & 0xffffffffu); }

constexpr int kTetEdges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

class Refiner {
 public:
  Refiner(const TetMesh& base, const MeshRefinement& spec) : spec_(spec) {
    const int n = static_cast<int>(base.positions.cols());
    x_.reserve(n + n / 4);
    for (int i = 0; i < n; ++i) x_.push_back(base.positions.col(i));
    tets_ = base.tetrahedra;
    region_ = base.tetrahedron_region;
    region_.resize(tets_.size(), 0);
    for (const SurfaceGroup& g : base.surface_groups) {
      std::vector<uint8_t> member(n, 0);
      for (int v : g.nodes) member[v] = 1;
      in_group_.push_back(std::move(member));
    }
    // The surface's normals at its vertices, (7.1a): each boundary face's outward normal, listed
    // at each of its vertices with Max's weight (e1 x e2) / (|e1|^2 |e2|^2) (e1, e2 the face's
    // edges from that vertex), whose sum is the exact normal at a vertex of a mesh inscribed in
    // a sphere however irregular the facets (N. Max, J. Graphics Tools 4(2), 1999).
    surface_normals_.resize(n);
    const auto faces = base.boundary_faces.empty() ? tetrahedra_boundary_faces(base.positions, base.tetrahedra)
                                                   : base.boundary_faces;
    for (const auto& f : faces)
      for (int k = 0; k < 3; ++k) {
        const Vec3 e1 = x_[f[(k + 1) % 3]] - x_[f[k]], e2 = x_[f[(k + 2) % 3]] - x_[f[k]];
        surface_normals_[f[k]].push_back(e1.cross(e2) / (e1.squaredNorm() * e2.squaredNorm()));
      }
    edge_tets_.reserve(8 * tets_.size());
    for (int t = 0; t < static_cast<int>(tets_.size()); ++t) add_edges(t);
  }

  void run() {
    // Passes until every tetrahedron is small enough: a tetrahedron cut by the propagation of
    // a later one may have a child nearer the focus that needs cutting again.
    for (bool changed = true; changed;) {
      changed = false;
      for (size_t t = 0; t < tets_.size(); ++t)
        while (too_long(static_cast<int>(t))) {
          bisect(longest_edge(static_cast<int>(t)));
          changed = true;
        }
    }
  }

  TetMesh result(const TetMesh& base) const {
    TetMesh out;
    const int n = static_cast<int>(x_.size());
    out.positions.resize(3, n);
    for (int i = 0; i < n; ++i) out.positions.col(i) = x_[i];
    out.tetrahedra = tets_;
    out.tetrahedron_region = region_;
    out.nodal_volume.assign(n, 0.0);
    for (const auto& t : tets_) {
      const double v = tet_volume(t);
      for (int a : t) out.nodal_volume[a] += 0.25 * v;
      out.total_volume += v;
    }
    out.boundary_faces = tetrahedra_boundary_faces(out.positions, out.tetrahedra);
    out.unused_nodes = base.unused_nodes;
    out.ignored_elements = base.ignored_elements;
    out.reoriented = base.reoriented;
    out.physical_names = base.physical_names;
    for (size_t g = 0; g < base.surface_groups.size(); ++g) {
      SurfaceGroup group{base.surface_groups[g].tag, base.surface_groups[g].name, {}};
      for (int i = 0; i < n; ++i)
        if (in_group_[g][i]) group.nodes.push_back(i);
      out.surface_groups.push_back(std::move(group));
    }
    return out;
  }

 private:
  double tet_volume(const std::array<int, 4>& t) const {
    const Vec3& a = x_[t[0]];
    return (x_[t[1]] - a).dot((x_[t[2]] - a).cross(x_[t[3]] - a)) / 6.0;
  }
  double length2(EdgeKey e) const { return (x_[edge_first(e)] - x_[edge_second(e)]).squaredNorm(); }
  // The strict order of edges: by length, ties by the key (so the longest edge is unique).
  bool longer(EdgeKey e, EdgeKey f) const {
    const double le = length2(e), lf = length2(f);
    return le > lf || (le == lf && e > f);
  }
  EdgeKey longest_edge(int t) const {
    const auto& v = tets_[t];
    EdgeKey best = edge_key(v[0], v[1]);
    for (int k = 1; k < 6; ++k) {
      const EdgeKey e = edge_key(v[kTetEdges[k][0]], v[kTetEdges[k][1]]);
      if (longer(e, best)) best = e;
    }
    return best;
  }
  double mean_edge(int t) const {
    const auto& v = tets_[t];
    double sum = 0;
    for (const auto& k : kTetEdges) sum += (x_[v[k[0]]] - x_[v[k[1]]]).norm();
    return sum / 6;
  }
  bool too_long(int t) const {
    const auto& v = tets_[t];
    const Vec3 centroid = 0.25 * (x_[v[0]] + x_[v[1]] + x_[v[2]] + x_[v[3]]);
    const double h = refinement_size(spec_, (centroid - spec_.focus).norm());
    return h < spec_.max_size && mean_edge(t) > h;
  }
  void add_edges(int t) {
    const auto& v = tets_[t];
    for (const auto& k : kTetEdges) edge_tets_[edge_key(v[k[0]], v[k[1]])].push_back(t);
  }
  void remove_edges(int t) {
    const auto& v = tets_[t];
    for (const auto& k : kTetEdges) {
      std::vector<int>& list = edge_tets_[edge_key(v[k[0]], v[k[1]])];
      list.erase(std::find(list.begin(), list.end(), t));
    }
  }

  // Cuts every tetrahedron around e through e's midpoint, once each of them has e as its
  // longest edge (LEPP: the others are cut first, through their own longest edges, which are
  // longer than e, so the recursion ends).
  void bisect(EdgeKey e) {
    for (;;) {
      const auto it = edge_tets_.find(e);
      if (it == edge_tets_.end() || it->second.empty()) return;
      int blocker = -1;
      for (int s : it->second)
        if (longest_edge(s) != e) {
          blocker = s;
          break;
        }
      if (blocker < 0) break;
      bisect(longest_edge(blocker));
    }
    const int a = edge_first(e), b = edge_second(e);
    const std::vector<int> around = edge_tets_[e];
    if (static_cast<int64_t>(x_.size()) >= kMaxMeshNodes)
      throw std::invalid_argument("mesh refinement: more than " + std::to_string(kMaxMeshNodes) +
                                  " nodes (focus_size too small for this body)");
    // The faces (a, b, c) around e that belong to one tetrahedron only are boundary faces: c
    // appears once among the tetrahedra's other vertices. Their third vertices decide the
    // midpoint's surface groups, their outward normals where it goes (7.1a).
    std::vector<int> third;
    for (int s : around)
      for (int v : tets_[s])
        if (v != a && v != b) third.push_back(v);
    std::vector<int> boundary_third;
    std::vector<Vec3> face_normals;  // the outward unit normals of those faces
    for (int s : around) {
      int c[2], k = 0;
      for (int u : tets_[s])
        if (u != a && u != b) c[k++] = u;
      for (int j = 0; j < 2; ++j)
        if (std::count(third.begin(), third.end(), c[j]) == 1) {
          Vec3 normal = (x_[b] - x_[a]).cross(x_[c[j]] - x_[a]);
          if (normal.dot(x_[c[1 - j]] - x_[a]) > 0) normal = -normal;  // away from the tetrahedron's fourth vertex
          boundary_third.push_back(c[j]);
          face_normals.push_back(normal.normalized());
        }
    }
    const int m = static_cast<int>(x_.size());
    x_.push_back(boundary_midpoint(a, b, face_normals, around));
    for (auto& member : in_group_) {
      bool in = false;
      if (member[a] && member[b])
        for (int c : boundary_third) in = in || member[c];
      member.push_back(in ? 1 : 0);
    }
    for (int s : around) {
      remove_edges(s);
      std::array<int, 4> first = tets_[s], second = tets_[s];
      for (int k = 0; k < 4; ++k) {
        if (first[k] == b) first[k] = m;   // replacing one vertex by a point of its edge keeps the orientation
        if (second[k] == a) second[k] = m;
      }
      tets_[s] = first;
      add_edges(s);
      tets_.push_back(second);
      region_.push_back(region_[s]);
      add_edges(static_cast<int>(tets_.size()) - 1);
    }
    edge_tets_.erase(e);
  }

  // The unit normal of the surface at boundary vertex v on the side whose faces' normal is
  // `side`: its listed normals within the crease angle of `side`, summed (side when none is).
  Vec3 smooth_normal(int v, const Vec3& side) const {
    Vec3 sum = Vec3::Zero();
    for (const Vec3& w : surface_normals_[v])
      if (w.dot(side) >= kCreaseCosine * w.norm()) sum += w;
    return sum.squaredNorm() > 0 ? Vec3(sum.normalized()) : side;
  }

  // The new vertex on edge (a, b), (7.1a): the midpoint, or on a boundary edge inside a smooth
  // surface (its two faces' normals within the crease angle) the midpoint of the cubic Hermite
  // curve from a to b whose tangents lie in the surface's tangent planes at a and b, so that a
  // curved body's new surface vertices lie on the curved surface and not on its facets (on a
  // sphere of radius R_b the offset is |b - a|^2 / (8 R_b) along the normal, the facet's sag;
  // on a flat face it is zero). Records the new vertex's surface normals for later cuts. The
  // offset is dropped if it would turn a child tetrahedron inside out.
  Vec3 boundary_midpoint(int a, int b, const std::vector<Vec3>& face_normals, const std::vector<int>& around) {
    const Vec3 mid = 0.5 * (x_[a] + x_[b]);
    surface_normals_.emplace_back();
    if (face_normals.size() != 2) return mid;  // interior (or a non-manifold edge: left straight)
    const Vec3 &f1 = face_normals[0], &f2 = face_normals[1];
    std::vector<Vec3>& normals = surface_normals_.back();
    if (f1.dot(f2) < kCreaseCosine) {  // a crease (a box's edge, the dome's rim): straight, a normal per side
      normals = {(smooth_normal(a, f1) + smooth_normal(b, f1)).normalized(),
                 (smooth_normal(a, f2) + smooth_normal(b, f2)).normalized()};
      return mid;
    }
    const Vec3 side = (f1 + f2).normalized();
    const Vec3 na = smooth_normal(a, side), nb = smooth_normal(b, side);
    normals = {(na + nb).normalized()};
    const Vec3 ab = x_[b] - x_[a];
    const Vec3 offset = (ab.dot(nb) * nb - ab.dot(na) * na) / 8.0;  // (P'(0) - P'(1)) / 8 of the Hermite curve
    if (offset.squaredNorm() == 0) return mid;
    const Vec3 curved = mid + offset;
    for (int s : around)  // each child replaces b (or a) by the new vertex: both must stay positive
      for (int replaced : {a, b}) {
        std::array<int, 4> t = tets_[s];
        Vec3 p[4];
        for (int k = 0; k < 4; ++k) p[k] = t[k] == replaced ? curved : x_[t[k]];
        if ((p[1] - p[0]).dot((p[2] - p[0]).cross(p[3] - p[0])) <= 0) return mid;
      }
    return curved;
  }

  static constexpr double kCreaseCosine = 0.8660254037844387;  // cos 30 degrees

  const MeshRefinement& spec_;
  std::vector<Vec3> x_;
  std::vector<std::vector<Vec3>> surface_normals_;  // per vertex: weighted outward normals (none inside)
  std::vector<std::array<int, 4>> tets_;
  std::vector<int64_t> region_;
  std::vector<std::vector<uint8_t>> in_group_;  // per surface group, per vertex
  std::unordered_map<EdgeKey, std::vector<int>> edge_tets_;
};

// The point of triangle (a, b, c) nearest to p (Ericson, Real-Time Collision Detection, 5.1.5).
Vec3 nearest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

}  // namespace

TetMesh refine_mesh(const TetMesh& base, const MeshRefinement& spec) {
  if (!(spec.focus_size > 0) || !std::isfinite(spec.focus_size))
    throw std::invalid_argument("mesh refinement: focus_size must be a positive length (m)");
  if (!(spec.growth > 1) || !std::isfinite(spec.growth))
    throw std::invalid_argument("mesh refinement: growth must exceed 1");
  if (!(spec.max_size > 0)) throw std::invalid_argument("mesh refinement: max_size must be positive (m)");
  if (!spec.focus.allFinite()) throw std::invalid_argument("mesh refinement: the focus is not finite");
  Refiner refiner(base, spec);
  refiner.run();
  return refiner.result(base);
}

Vec3 nearest_boundary_point(const TetMesh& mesh, const Vec3& p) {
  Vec3 best = p;
  double best2 = INFINITY;
  for (const auto& f : mesh.boundary_faces) {
    const Vec3 q = nearest_on_triangle(p, mesh.positions.col(f[0]), mesh.positions.col(f[1]), mesh.positions.col(f[2]));
    const double d2 = (q - p).squaredNorm();
    if (d2 < best2) {
      best2 = d2;
      best = q;
    }
  }
  return best;
}

}  // namespace palpate
