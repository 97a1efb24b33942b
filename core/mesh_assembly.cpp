// A mesh read from a file checked and assembled (mesh_parse.h, the rules in mesh_reader.h):
// degenerate, inverted, unused nodes, coincident nodes, overlapping faces, one part; then the
// derived data: TetGen's mid-edge nodes dropped, the nodal volumes lumped, the boundary faces
// and the physical surface groups' nodes.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>

#include "core/mesh_parse.h"

namespace palpate {

using namespace mesh_io;

namespace {

// A tetrahedron is degenerate when |V| <= kDegenerate * L^3 (a regular one has 0.118 L^3).
constexpr double kDegenerate = 1e-12;

// Union-find over the tetrahedra (path halving, union by size).
struct Parts {
  explicit Parts(size_t n) : parent(n), size(n, 1) {
    for (size_t i = 0; i < n; ++i) parent[i] = static_cast<int64_t>(i);
  }
  int64_t root(int64_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  }
  void join(int64_t a, int64_t b) {
    a = root(a);
    b = root(b);
    if (a == b) return;
    if (size[a] < size[b]) std::swap(a, b);
    parent[b] = a;
    size[a] += size[b];
  }
  std::vector<int64_t> parent, size;
};

// Refuses a mesh that is not one part. Faces: each triangle shared by two tetrahedra
// joins them; one shared by three or more is an overlap. `tets` index kept nodes.
void check_one_part(const RawMesh& raw, const std::vector<std::array<int64_t, 4>>& tets, const std::string& element_file) {
  const size_t m = tets.size();
  struct Face {
    std::array<int64_t, 3> v;
    int64_t tet;
    int64_t opposite;  // the tetrahedron's fourth node
  };
  std::vector<Face> faces;
  faces.reserve(4 * m);
  for (size_t t = 0; t < m; ++t)
    for (int skip = 0; skip < 4; ++skip) {
      Face f{{}, static_cast<int64_t>(t), tets[t][skip]};
      int k = 0;
      for (int a = 0; a < 4; ++a)
        if (a != skip) f.v[k++] = tets[t][a];
      std::sort(f.v.begin(), f.v.end());
      faces.push_back(f);
    }
  std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) { return a.v != b.v ? a.v < b.v : a.tet < b.tet; });
  Parts by_face(m);
  for (size_t k = 1; k < faces.size(); ++k) {
    if (faces[k].v != faces[k - 1].v) continue;
    if (k >= 2 && faces[k].v == faces[k - 2].v) {
      const int64_t t0 = faces[k - 2].tet, t1 = faces[k - 1].tet, t2 = faces[k].tet;
      fail_at(element_file, raw.tet_line[t2],
              "tetrahedron " + std::to_string(raw.tet_tag[t2]) + " shares a face with tetrahedra " +
                  std::to_string(raw.tet_tag[t0]) + " (line " + std::to_string(raw.tet_line[t0]) + ") and " +
                  std::to_string(raw.tet_tag[t1]) + " (line " + std::to_string(raw.tet_line[t1]) +
                  "): a face bounds at most two tetrahedra (duplicated or overlapping elements)");
    }
    if (faces[k].opposite == faces[k - 1].opposite) {
      const int64_t t0 = faces[k - 1].tet, t1 = faces[k].tet;
      fail_at(element_file, raw.tet_line[t1],
              "tetrahedron " + std::to_string(raw.tet_tag[t1]) + " repeats tetrahedron " + std::to_string(raw.tet_tag[t0]) +
                  " (line " + std::to_string(raw.tet_line[t0]) + "): the same four nodes");
    }
    by_face.join(faces[k].tet, faces[k - 1].tet);
  }
  const auto tetrahedra = [](int64_t n) { return std::to_string(n) + (n == 1 ? " tetrahedron" : " tetrahedra"); };
  int64_t parts = 0, largest = -1;
  for (size_t t = 0; t < m; ++t)
    if (by_face.root(t) == static_cast<int64_t>(t)) {
      ++parts;
      if (largest < 0 || by_face.size[t] > by_face.size[largest]) largest = static_cast<int64_t>(t);
    }
  if (parts == 1) return;
  // The first elements (in file order) of the largest part and outside it.
  size_t first = 0, first_largest = 0;
  while (by_face.root(first) == largest) ++first;
  while (by_face.root(first_largest) != largest) ++first_largest;
  // Do the parts touch at nodes (a pinch) or not at all?
  Parts by_node(m);
  std::vector<int64_t> tet_of_node;
  {
    int64_t n = 0;
    for (const auto& t : tets)
      for (int64_t v : t) n = std::max(n, v + 1);
    tet_of_node.assign(n, -1);
  }
  for (size_t t = 0; t < m; ++t)
    for (int64_t v : tets[t]) {
      if (tet_of_node[v] < 0) tet_of_node[v] = static_cast<int64_t>(t);
      else by_node.join(tet_of_node[v], static_cast<int64_t>(t));
    }
  int64_t node_parts = 0;
  for (size_t t = 0; t < m; ++t) node_parts += by_node.root(t) == static_cast<int64_t>(t);
  const std::string how =
      node_parts == 1        ? "; they touch only at edges or nodes (a pinch: no material joins them)"
      : node_parts == parts ? ", and no part shares a node with another"
                            : "; some touch at edges or nodes, " + std::to_string(node_parts) + " groups of them share no node";
  fail_at(element_file, raw.tet_line[first],
          "the tetrahedra form " + std::to_string(parts) + " parts joined by no shared face" + how +
              ": a body must be one part. Tetrahedron " + std::to_string(raw.tet_tag[first]) + " (this line) is in a part of " +
              tetrahedra(by_face.size[by_face.root(first)]) + ", the largest part has " +
              std::to_string(by_face.size[largest]) + " (tetrahedron " + std::to_string(raw.tet_tag[first_largest]) +
              ", line " + std::to_string(raw.tet_line[first_largest]) + "); mesh one volume, or remove the other parts");
}

}  // namespace

std::vector<std::array<int, 3>> tetrahedra_boundary_faces(const Points& X, const std::vector<std::array<int, 4>>& tets) {
  struct Face {
    std::array<int, 3> key;  // sorted
    std::array<int, 3> v;    // as taken from the tetrahedron
    int opposite;
  };
  std::vector<Face> faces;
  faces.reserve(4 * tets.size());
  for (const auto& t : tets)
    for (int skip = 0; skip < 4; ++skip) {
      Face f{{}, {}, t[skip]};
      int k = 0;
      for (int a = 0; a < 4; ++a)
        if (a != skip) f.v[k++] = t[a];
      f.key = f.v;
      std::sort(f.key.begin(), f.key.end());
      faces.push_back(f);
    }
  std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) { return a.key < b.key; });
  std::vector<std::array<int, 3>> out;
  for (size_t k = 0; k < faces.size();) {
    size_t end = k + 1;
    while (end < faces.size() && faces[end].key == faces[k].key) ++end;
    if (end == k + 1) {
      std::array<int, 3> v = faces[k].v;
      const Vec3 a = X.col(v[0]);
      const Vec3 normal = (X.col(v[1]) - a).cross(X.col(v[2]) - a);
      if (normal.dot(X.col(faces[k].opposite) - a) > 0) std::swap(v[1], v[2]);
      out.push_back(v);
    }
    k = end;
  }
  return out;
}

namespace mesh_io {

TetMesh assemble(RawMesh raw, const std::string& node_file, const std::string& element_file,
                 const std::string& what_if_empty) {
  if (raw.tets.empty()) throw std::runtime_error(element_file + ": " + what_if_empty);
  TetMesh mesh;
  mesh.ignored_elements = raw.ignored_elements;
  mesh.physical_names = std::move(raw.physical_names);
  const size_t node_count = raw.nodes.size();
  std::vector<double> volume(raw.tets.size());
  int64_t positive = 0;
  for (size_t t = 0; t < raw.tets.size(); ++t) {
    const auto& tet = raw.tets[t];
    const std::string name = "tetrahedron " + std::to_string(raw.tet_tag[t]);
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        if (tet[a] == tet[b])
          fail_at(element_file, raw.tet_line[t], name + " uses node " + std::to_string(raw.node_tag[tet[a]]) + " (line " +
                                                     std::to_string(raw.node_line[tet[a]]) + ") twice (degenerate)");
    const Vec3& x0 = raw.nodes[tet[0]];
    const Vec3 e1 = raw.nodes[tet[1]] - x0, e2 = raw.nodes[tet[2]] - x0, e3 = raw.nodes[tet[3]] - x0;
    const double V = e1.dot(e2.cross(e3)) / 6.0;  // signed volume
    double L2 = std::max({e1.squaredNorm(), e2.squaredNorm(), e3.squaredNorm()});
    for (int a = 1; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) L2 = std::max(L2, (raw.nodes[tet[a]] - raw.nodes[tet[b]]).squaredNorm());
    const double L = std::sqrt(L2);
    if (!(std::abs(V) > kDegenerate * L * L * L))
      fail_at(element_file, raw.tet_line[t], name + " is degenerate: volume " + format_number(V) + " m^3 with longest edge " + format_number(L) +
                                                 " m (|V| must exceed 1e-12 L^3): its four nodes are (nearly) in one plane");
    positive += V > 0;
    volume[t] = V;
  }
  // The file's orientation: the sign most tetrahedra have (ties: gmsh's, positive).
  const int64_t negative = static_cast<int64_t>(raw.tets.size()) - positive;
  const bool file_positive = positive >= negative;
  for (size_t t = 0; t < raw.tets.size(); ++t) {
    if ((volume[t] > 0) == file_positive) continue;
    const auto& tet = raw.tets[t];
    fail_at(element_file, raw.tet_line[t],
            "tetrahedron " + std::to_string(raw.tet_tag[t]) + " is inverted: signed volume " + format_number(volume[t]) + " m^3 (nodes " +
                std::to_string(raw.node_tag[tet[0]]) + " " + std::to_string(raw.node_tag[tet[1]]) + " " +
                std::to_string(raw.node_tag[tet[2]]) + " " + std::to_string(raw.node_tag[tet[3]]) + ": seen from the fourth, the first three turn " +
                (volume[t] > 0 ? "counterclockwise" : "clockwise") + ") while " +
                std::to_string(file_positive ? positive : negative) + " of the file's " + std::to_string(raw.tets.size()) +
                " tetrahedra are " + (file_positive ? "positive" : "negative") +
                ": the mesh is tangled or this element's nodes are misnumbered (regenerate the mesh, or swap two of its nodes)");
  }
  mesh.reoriented = !file_positive;
  for (double& V : volume) V = std::abs(V);

  // Every node must be referenced by a tetrahedron; the corners are kept, in file order.
  std::vector<int64_t> new_index(node_count, -1);
  for (const auto& tet : raw.tets)
    for (int64_t v : tet) new_index[v] = 0;
  raw.mid_edge.resize(node_count, 0);
  for (size_t i = 0; i < node_count; ++i)
    if (new_index[i] < 0 && !raw.mid_edge[i])
      fail_at(node_file, raw.node_line[i],
              "node " + std::to_string(raw.node_tag[i]) + " is used by no tetrahedron (a geometry point, or a node of "
              "lower-dimensional elements only): every node must be a vertex of the body's tetrahedra; remove it, or "
              "regenerate the mesh without free points");
  int64_t kept = 0;
  for (size_t i = 0; i < node_count; ++i)
    if (new_index[i] == 0) new_index[i] = kept++;
  mesh.unused_nodes = static_cast<int64_t>(node_count) - kept;
  mesh.positions.resize(3, kept);
  std::vector<int> kept_line(kept);
  for (size_t i = 0; i < node_count; ++i)
    if (new_index[i] >= 0) {
      mesh.positions.col(new_index[i]) = raw.nodes[i];
      kept_line[new_index[i]] = raw.node_line[i];
    }

  // Coincident nodes would make a crack (two tetrahedra sharing a point but not a node)
  // and a zero particle spacing.
  std::vector<int64_t> order(kept);
  for (int64_t i = 0; i < kept; ++i) order[i] = i;
  const Points& X = mesh.positions;
  auto less = [&X](int64_t a, int64_t b) {
    for (int c = 0; c < 3; ++c)
      if (X(c, a) != X(c, b)) return X(c, a) < X(c, b);
    return a < b;
  };
  std::sort(order.begin(), order.end(), less);
  for (int64_t k = 1; k < kept; ++k)
    if (X.col(order[k]) == X.col(order[k - 1])) {
      const int64_t a = std::min(order[k], order[k - 1]), b = std::max(order[k], order[k - 1]);
      fail_at(node_file, kept_line[b], "this node coincides with the node at line " + std::to_string(kept_line[a]) + " (" +
                                    format_number(X(0, a)) + ", " + format_number(X(1, a)) + ", " + format_number(X(2, a)) + ")");
    }

  // One body: the tetrahedra connected through shared faces.
  std::vector<std::array<int64_t, 4>> kept_tets(raw.tets.size());
  for (size_t t = 0; t < raw.tets.size(); ++t)
    for (int a = 0; a < 4; ++a) kept_tets[t][a] = new_index[raw.tets[t][a]];
  check_one_part(raw, kept_tets, element_file);

  // Tetrahedra, positively oriented, and the lumped volumes v_i = sum_t |V_t| / 4.
  mesh.tetrahedra.resize(raw.tets.size());
  mesh.nodal_volume.assign(kept, 0.0);
  for (size_t t = 0; t < raw.tets.size(); ++t) {
    std::array<int, 4> tet;
    for (int a = 0; a < 4; ++a) tet[a] = static_cast<int>(kept_tets[t][a]);
    if (mesh.reoriented) std::swap(tet[1], tet[2]);
    mesh.tetrahedra[t] = tet;
    for (int v : tet) mesh.nodal_volume[v] += 0.25 * volume[t];
    mesh.total_volume += volume[t];
  }
  mesh.tetrahedron_region = raw.tet_region;
  mesh.tetrahedron_region.resize(raw.tets.size(), 0);
  mesh.boundary_faces = tetrahedra_boundary_faces(mesh.positions, mesh.tetrahedra);
  // The boundary must enclose what the tetrahedra hold (divergence theorem: sum over the
  // outward faces of (x . n) A / 3): tetrahedra that interpenetrate without sharing a face,
  // or fold over one another, hold more volume than their boundary encloses.
  {
    const Vec3 origin = mesh.positions.col(0);
    const double L = (mesh.positions.rowwise().maxCoeff() - mesh.positions.rowwise().minCoeff()).norm();
    double enclosed = 0;
    for (const auto& f : mesh.boundary_faces) {
      const Vec3 a = mesh.positions.col(f[0]) - origin, b = mesh.positions.col(f[1]) - origin,
                 c = mesh.positions.col(f[2]) - origin;
      enclosed += (a + b + c).dot((b - a).cross(c - a)) / 18.0;
    }
    const double round_off = 1e-12 * static_cast<double>(mesh.boundary_faces.size()) * L * L * L;
    if (!(std::abs(enclosed - mesh.total_volume) <= 1e-6 * mesh.total_volume + round_off)) {
      throw std::runtime_error(element_file + ": the tetrahedra overlap: they hold " + format_number(mesh.total_volume) +
                               " m^3 but their boundary encloses " + format_number(enclosed) +
                               " m^3 (tetrahedra that interpenetrate or fold over one another without sharing faces)");
    }
  }

  // Physical surface groups: the kept nodes of their triangles (every triangle node is a
  // tetrahedron's node: the unused-node check above refused the others).
  std::map<int64_t, std::vector<int>> group_nodes;
  for (size_t k = 0; k < raw.triangles.size(); ++k) {
    std::vector<int>& nodes = group_nodes[raw.triangle_group[k]];
    for (int64_t v : raw.triangles[k]) nodes.push_back(static_cast<int>(new_index[v]));
  }
  for (auto& [tag, nodes] : group_nodes) {
    std::sort(nodes.begin(), nodes.end());
    nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
    SurfaceGroup g;
    g.tag = tag;
    for (const PhysicalName& p : mesh.physical_names)
      if (p.dimension == 2 && p.tag == tag) g.name = p.name;
    g.nodes = std::move(nodes);
    mesh.surface_groups.push_back(std::move(g));
  }
  return mesh;
}

}  // namespace mesh_io

}  // namespace palpate
