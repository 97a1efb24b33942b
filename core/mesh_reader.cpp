// Tetrahedral mesh files -> node positions, tetrahedra and nodal volumes (mesh_reader.h).
//
// Both formats are read by one whitespace tokenizer that knows the line of every
// token (for messages) and, for TetGen, skips '#' comments. Node references are
// resolved after the whole file is read; assemble() then checks the mesh
// (degenerate, inverted, unused nodes, coincident nodes, overlapping faces, one part:
// the rules in mesh_reader.h), drops TetGen's mid-edge nodes and lumps the volumes.
#include "core/mesh_reader.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <map>
#include <unordered_map>
#include <utility>

namespace palpate {

namespace fs = std::filesystem;

namespace {

// Coordinates beyond this are refused: volumes of larger values could overflow.
constexpr double kMaxCoordinate = 1e12;  // m
// A tetrahedron is degenerate when |V| <= kDegenerate * L^3 (a regular one has 0.118 L^3).
constexpr double kDegenerate = 1e-12;

std::string fmt(double x) {
  std::ostringstream s;
  s.precision(6);
  s << x;
  return s.str();
}

// The text of a token for a message: at most 40 bytes, control bytes escaped.
std::string quoted(std::string_view token) {
  std::string out = "'";
  for (size_t i = 0; i < token.size() && i < 40; ++i) {
    const unsigned char c = static_cast<unsigned char>(token[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      static constexpr char kHex[] = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  if (token.size() > 40) out += "...";
  return out + "'";
}

std::string read_text(const fs::path& file, const char* what) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw std::runtime_error(file.string() + ": cannot open " + what);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw std::runtime_error(file.string() + ": cannot read " + what);
  return text;
}

// Whitespace-separated tokens with their line numbers.
class Lexer {
 public:
  Lexer(std::string text, std::string file, bool hash_comments)
      : text_(std::move(text)), file_(std::move(file)), hash_comments_(hash_comments) {}

  // The next token, or false at the end of the input.
  bool next(std::string_view& token) {
    skip_space();
    if (pos_ >= text_.size()) {
      token_line_ = line_;
      return false;
    }
    const size_t start = pos_;
    while (pos_ < text_.size() && !is_space(text_[pos_]) && !(hash_comments_ && text_[pos_] == '#')) ++pos_;
    token = std::string_view(text_).substr(start, pos_ - start);
    token_line_ = line_;
    return true;
  }

  // The next token, which must exist: `what` says what was expected.
  std::string_view expect(const std::string& what) {
    std::string_view token;
    if (!next(token)) fail("unexpected end of file, expected " + what);
    return token;
  }

  // True if another token follows on the line of the last token.
  bool more_on_line() {
    skip_space(/*stop_at_newline=*/true);
    return pos_ < text_.size() && text_[pos_] != '\n';
  }
  // Requires the line of the last token to end here.
  void end_of_line(const std::string& what) {
    if (more_on_line()) {
      std::string_view extra;
      next(extra);
      token_line_ = line_;
      fail("unexpected " + quoted(extra) + " after " + what);
    }
  }
  // Skips the rest of the current line.
  void skip_line() {
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
  }

  int64_t integer(const std::string& what, int64_t lo, int64_t hi) {
    const std::string_view t = expect(what);
    std::string_view digits = t;
    if (!digits.empty() && digits[0] == '+') digits.remove_prefix(1);
    int64_t value = 0;
    const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    if (ec != std::errc() || end != digits.data() + digits.size() || digits.empty())
      fail(what + ": expected an integer, got " + quoted(t));
    if (value < lo || value > hi)
      fail(what + ": must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + std::to_string(value));
    return value;
  }

  double real(const std::string& what) {
    const std::string_view t = expect(what);
    std::string_view digits = t;
    if (!digits.empty() && digits[0] == '+') digits.remove_prefix(1);
    double value = 0;
    const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    if (ec == std::errc::result_out_of_range) fail(what + ": " + quoted(t) + " is out of range");
    if (ec != std::errc() || end != digits.data() + digits.size() || digits.empty())
      fail(what + ": expected a number, got " + quoted(t));
    if (!std::isfinite(value)) fail(what + ": must be a finite number, got " + quoted(t));
    if (std::abs(value) > kMaxCoordinate) fail(what + ": |" + quoted(t) + "| exceeds " + fmt(kMaxCoordinate));
    return value;
  }

  // A double-quoted string on the current line (gmsh names: no escapes), without the quotes.
  std::string string_literal(const std::string& what) {
    skip_space();
    token_line_ = line_;
    if (pos_ >= text_.size()) fail("unexpected end of file, expected " + what);
    if (text_[pos_] != '"') {
      std::string_view token;
      next(token);
      fail(what + ": expected a name in double quotes, got " + quoted(token));
    }
    const size_t start = ++pos_;
    while (pos_ < text_.size() && text_[pos_] != '"' && text_[pos_] != '\n') ++pos_;
    if (pos_ >= text_.size() || text_[pos_] != '"') fail(what + ": the closing double quote is missing on this line");
    return text_.substr(start, pos_++ - start);
  }

  int line() const { return token_line_; }
  const std::string& file() const { return file_; }

  [[noreturn]] void fail(const std::string& reason) const { fail_at(token_line_, reason); }
  [[noreturn]] void fail_at(int line, const std::string& reason) const {
    throw std::runtime_error(file_ + ":" + std::to_string(line) + ": " + reason);
  }

 private:
  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }
  void skip_space(bool stop_at_newline = false) {
    while (pos_ < text_.size()) {
      const char c = text_[pos_];
      if (c == '\n') {
        if (stop_at_newline) return;
        ++line_;
        ++pos_;
      } else if (is_space(c)) {
        ++pos_;
      } else if (hash_comments_ && c == '#') {
        skip_line();
      } else {
        return;
      }
    }
  }

  std::string text_;
  std::string file_;
  bool hash_comments_;
  size_t pos_ = 0;
  int line_ = 1;
  int token_line_ = 1;
};

[[noreturn]] void fail_at(const std::string& file, int line, const std::string& reason) {
  throw std::runtime_error(file + ":" + std::to_string(line) + ": " + reason);
}

// What both readers collect before the mesh is checked and assembled.
struct RawMesh {
  std::vector<Vec3> nodes;
  std::vector<int> node_line;                  // line of each node, for messages
  std::vector<int64_t> node_tag;               // the node's number in the file
  std::vector<char> mid_edge;                  // TetGen 10-node: referenced as a mid-edge node
  std::vector<std::array<int64_t, 4>> tets;    // node indices into `nodes` (resolved)
  std::vector<int> tet_line;
  std::vector<int64_t> tet_tag;                // the element's number in the file
  std::vector<int64_t> tet_region;             // physical volume tag (TetGen: region attribute), 0 = none
  std::vector<std::array<int64_t, 3>> triangles;  // gmsh triangles of a physical surface (indices into `nodes`)
  std::vector<int64_t> triangle_group;         // their physical surface tag
  int64_t ignored_elements = 0;
  std::vector<PhysicalName> physical_names;
};

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

namespace {

// Checks the tetrahedra, drops mid-edge nodes, lumps the volumes. Messages name
// `node_file` or `element_file` (the same file for gmsh).
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
      fail_at(element_file, raw.tet_line[t], name + " is degenerate: volume " + fmt(V) + " m^3 with longest edge " + fmt(L) +
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
            "tetrahedron " + std::to_string(raw.tet_tag[t]) + " is inverted: signed volume " + fmt(volume[t]) + " m^3 (nodes " +
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
                                    fmt(X(0, a)) + ", " + fmt(X(1, a)) + ", " + fmt(X(2, a)) + ")");
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
      std::ostringstream o;
      o << element_file << ": the tetrahedra overlap: they hold " << mesh.total_volume
        << " m^3 but their boundary encloses " << enclosed
        << " m^3 (tetrahedra that interpenetrate or fold over one another without sharing faces)";
      throw std::runtime_error(o.str());
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

// ---------------------------------------------------------------------------
// gmsh

enum class GmshVersion { none, v2, v41 };

// $MeshFormat: "version file-type data-size" and $EndMeshFormat.
GmshVersion read_mesh_format(Lexer& lex) {
  const std::string_view version = lex.expect("the format version");
  const int version_line = lex.line();
  GmshVersion v;
  if (version == "4.1") {
    v = GmshVersion::v41;
  } else if (version == "2.2" || version == "2.1" || version == "2" || version == "2.0") {
    v = GmshVersion::v2;
  } else if (version == "4" || version == "4.0") {
    lex.fail("gmsh format 4.0 is not supported: save the mesh as 4.1 or 2.2 ASCII (gmsh -format msh41 or msh22)");
  } else {
    lex.fail("unknown gmsh format version " + quoted(version) + " (known: 4.1, 2.2)");
  }
  const int64_t file_type = lex.integer("file-type", 0, 1);
  if (file_type != 0)
    lex.fail_at(version_line, "binary .msh files are not supported: save the mesh as ASCII (gmsh option Mesh.Binary = 0)");
  lex.integer("data-size", 1, 16);
  if (lex.expect("$EndMeshFormat") != "$EndMeshFormat") lex.fail("expected $EndMeshFormat");
  return v;
}

// Node tag -> index into raw.nodes (tags are positive and unique).
struct NodeTags {
  std::unordered_map<int64_t, int64_t> index;
  void add(Lexer& lex, int64_t tag, RawMesh& raw) {
    const auto [it, fresh] = index.emplace(tag, static_cast<int64_t>(raw.nodes.size()));
    if (!fresh)
      lex.fail("node tag " + std::to_string(tag) + " appears twice (first at line " +
               std::to_string(raw.node_line[it->second]) + ")");
  }
};

constexpr int64_t kMaxTag = std::numeric_limits<int64_t>::max() / 2;

Vec3 read_xyz(Lexer& lex) {
  Vec3 p;
  p[0] = lex.real("x");
  p[1] = lex.real("y");
  p[2] = lex.real("z");
  return p;
}

void read_nodes_v41(Lexer& lex, RawMesh& raw, NodeTags& tags, int64_t max_nodes) {
  const int64_t blocks = lex.integer("numEntityBlocks", 0, kMaxTag);
  const int64_t count = lex.integer("numNodes", 0, kMaxTag);
  if (count > max_nodes)
    lex.fail(std::to_string(count) + " nodes exceed the limit of " + std::to_string(max_nodes));
  lex.integer("minNodeTag", 0, kMaxTag);
  lex.integer("maxNodeTag", 0, kMaxTag);
  int64_t read = 0;
  for (int64_t b = 0; b < blocks; ++b) {
    const int64_t dim = lex.integer("entityDim", 0, 3);
    lex.integer("entityTag", -kMaxTag, kMaxTag);
    const int64_t parametric = lex.integer("parametric", 0, 1);
    const int64_t in_block = lex.integer("numNodesInBlock", 0, kMaxTag);
    if (in_block > count - read)
      lex.fail("the node blocks hold more than the " + std::to_string(count) + " nodes the $Nodes header declares");
    const size_t first = raw.nodes.size();
    for (int64_t k = 0; k < in_block; ++k) {
      const int64_t tag = lex.integer("nodeTag", 1, kMaxTag);
      tags.add(lex, tag, raw);
      raw.nodes.emplace_back(Vec3::Zero());
      raw.node_tag.push_back(tag);
      raw.node_line.push_back(lex.line());
    }
    for (int64_t k = 0; k < in_block; ++k) {
      const Vec3 p = read_xyz(lex);
      raw.node_line[first + k] = lex.line();  // messages point at the coordinates
      raw.nodes[first + k] = p;
      if (parametric)
        for (int64_t u = 0; u < dim; ++u) lex.real("parametric coordinate");
    }
    read += in_block;
  }
  if (read != count)
    lex.fail("the node blocks hold " + std::to_string(read) + " nodes, the $Nodes header says " + std::to_string(count));
}

void read_nodes_v2(Lexer& lex, RawMesh& raw, NodeTags& tags, int64_t max_nodes) {
  const int64_t count = lex.integer("number-of-nodes", 0, kMaxTag);
  if (count > max_nodes)
    lex.fail(std::to_string(count) + " nodes exceed the limit of " + std::to_string(max_nodes));
  for (int64_t k = 0; k < count; ++k) {
    const int64_t tag = lex.integer("node-number", 1, kMaxTag);
    tags.add(lex, tag, raw);
    raw.node_tag.push_back(tag);
    raw.nodes.push_back(read_xyz(lex));
    raw.node_line.push_back(lex.line());
    lex.end_of_line("a node's x y z");
  }
}

// A 4-node tetrahedron's node tags (gmsh); resolved later.
// A 4-node tetrahedron or a 3-node triangle (node tags, resolved later) with its
// physical group: 2.2 gives it directly, 4.1 through its entity's ($Entities).
struct GmshTet {
  int64_t tag;
  std::array<int64_t, 4> nodes;
  int line;
  int64_t physical = 0;  // 2.2: the first tag; 4.1: resolved from `entity`
  int64_t entity = 0;    // 4.1: the element block's entity tag
};
struct GmshTriangle {
  int64_t tag;
  std::array<int64_t, 3> nodes;
  int line;
  int64_t physical = 0;
  int64_t entity = 0;
};

void read_tet_nodes(Lexer& lex, int64_t tag, std::vector<GmshTet>& tets) {
  GmshTet t{tag, {}, 0};
  for (int a = 0; a < 4; ++a) t.nodes[a] = lex.integer("nodeTag", 1, kMaxTag);
  t.line = lex.line();
  lex.end_of_line("the four nodes of a tetrahedron");
  tets.push_back(t);
}

void read_triangle_nodes(Lexer& lex, int64_t tag, std::vector<GmshTriangle>& triangles) {
  GmshTriangle t{tag, {}, 0};
  for (int a = 0; a < 3; ++a) t.nodes[a] = lex.integer("nodeTag", 1, kMaxTag);
  t.line = lex.line();
  lex.end_of_line("the three nodes of a triangle");
  triangles.push_back(t);
}

constexpr int kGmshTriangle = 2;     // gmsh element type of the 3-node triangle
constexpr int kGmshTetrahedron = 4;  // gmsh element type of the 4-node tetrahedron

// $Entities (4.1): the physical tags of each (dimension, entity tag).
using EntityPhysicals = std::map<std::pair<int64_t, int64_t>, std::vector<int64_t>>;

void read_entities_v41(Lexer& lex, EntityPhysicals& physicals) {
  int64_t count[4];
  for (int d = 0; d < 4; ++d) count[d] = lex.integer("number of entities", 0, kMaxTag);
  for (int d = 0; d < 4; ++d)
    for (int64_t k = 0; k < count[d]; ++k) {
      const int64_t tag = lex.integer("entity tag", -kMaxTag, kMaxTag);
      for (int c = 0; c < (d == 0 ? 3 : 6); ++c) lex.real(d == 0 ? "point coordinate" : "bounding box coordinate");
      const int64_t n = lex.integer("numPhysicalTags", 0, 1000000);
      std::vector<int64_t>& tags = physicals[{d, tag}];
      for (int64_t p = 0; p < n; ++p) tags.push_back(lex.integer("physicalTag", -kMaxTag, kMaxTag));
      if (d > 0) {
        const int64_t bounding = lex.integer("number of bounding entities", 0, 1000000);
        for (int64_t b = 0; b < bounding; ++b) lex.integer("bounding entity tag", -kMaxTag, kMaxTag);
      }
      lex.end_of_line("an entity");
    }
}

void read_elements_v41(Lexer& lex, RawMesh& raw, std::vector<GmshTet>& tets, std::vector<GmshTriangle>& triangles) {
  const int64_t blocks = lex.integer("numEntityBlocks", 0, kMaxTag);
  const int64_t count = lex.integer("numElements", 0, kMaxTag);
  lex.integer("minElementTag", 0, kMaxTag);
  lex.integer("maxElementTag", 0, kMaxTag);
  int64_t read = 0;
  for (int64_t b = 0; b < blocks; ++b) {
    lex.integer("entityDim", 0, 3);
    const int64_t entity = lex.integer("entityTag", -kMaxTag, kMaxTag);
    const int64_t type = lex.integer("elementType", 1, 1000);
    const int64_t in_block = lex.integer("numElementsInBlock", 0, kMaxTag);
    if (in_block > count - read)
      lex.fail("the element blocks hold more than the " + std::to_string(count) +
               " elements the $Elements header declares");
    lex.end_of_line("an element block header");
    for (int64_t k = 0; k < in_block; ++k) {
      const int64_t tag = lex.integer("elementTag", 1, kMaxTag);
      if (type == kGmshTetrahedron) {
        read_tet_nodes(lex, tag, tets);
        tets.back().entity = entity;
      } else if (type == kGmshTriangle) {
        read_triangle_nodes(lex, tag, triangles);
        triangles.back().entity = entity;
        ++raw.ignored_elements;  // not a particle's element
      } else {  // one element per line: its node count need not be known
        lex.skip_line();
        ++raw.ignored_elements;
      }
    }
    read += in_block;
  }
  if (read != count)
    lex.fail("the element blocks hold " + std::to_string(read) + " elements, the $Elements header says " +
             std::to_string(count));
}

void read_elements_v2(Lexer& lex, RawMesh& raw, std::vector<GmshTet>& tets, std::vector<GmshTriangle>& triangles) {
  const int64_t count = lex.integer("number-of-elements", 0, kMaxTag);
  for (int64_t k = 0; k < count; ++k) {
    const int64_t tag = lex.integer("elm-number", 1, kMaxTag);
    const int64_t type = lex.integer("elm-type", 1, 1000);
    const int64_t tag_count = lex.integer("number-of-tags", 0, 1000);
    if (type != kGmshTetrahedron && type != kGmshTriangle) {
      lex.skip_line();
      ++raw.ignored_elements;
      continue;
    }
    int64_t physical = 0;  // the first tag
    for (int64_t t = 0; t < tag_count; ++t) {
      const int64_t value = lex.integer("tag", -kMaxTag, kMaxTag);
      if (t == 0) physical = value;
    }
    if (type == kGmshTetrahedron) {
      read_tet_nodes(lex, tag, tets);
      tets.back().physical = physical;
    } else {
      read_triangle_nodes(lex, tag, triangles);
      triangles.back().physical = physical;
      ++raw.ignored_elements;
    }
  }
}

// $PhysicalNames (4.1 and 2.2 alike): the count, then "dimension tag \"name\"" per line.
void read_physical_names(Lexer& lex, RawMesh& raw) {
  const int64_t count = lex.integer("numPhysicalNames", 0, kMaxTag);
  lex.end_of_line("the number of physical names");
  for (int64_t k = 0; k < count; ++k) {
    PhysicalName p;
    p.dimension = static_cast<int>(lex.integer("physical name dimension", 0, 3));
    p.line = lex.line();
    p.tag = lex.integer("physicalTag", 1, kMaxTag);
    if (lex.line() != p.line) lex.fail("physicalTag: expected on the line of its dimension");
    p.name = lex.string_literal("physical name");
    if (lex.line() != p.line) lex.fail("physical name: expected on the line of its dimension and tag");
    if (p.name.empty()) lex.fail("physical name: empty (\"\"): a group must be named to be referred to");
    lex.end_of_line("a physical name");
    for (const PhysicalName& q : raw.physical_names) {
      if (q.dimension == p.dimension && q.tag == p.tag)
        lex.fail("physical group " + std::to_string(p.tag) + " of dimension " + std::to_string(p.dimension) +
                 " is named twice (" + quoted(std::string_view(q.name)) + " at line " + std::to_string(q.line) + ", " + quoted(std::string_view(p.name)) + " here)");
      if (q.dimension == p.dimension && q.name == p.name)
        lex.fail("physical name " + quoted(std::string_view(p.name)) + " is given to two groups of dimension " + std::to_string(p.dimension) +
                 " (tag " + std::to_string(q.tag) + " at line " + std::to_string(q.line) + ", tag " + std::to_string(p.tag) +
                 " here): a name must identify one group");
    }
    raw.physical_names.push_back(std::move(p));
  }
}

// Reads "$End<name>" after a section's content.
void expect_end(Lexer& lex, std::string_view name) {
  const std::string end = "$End" + std::string(name);
  const std::string_view token = lex.expect(end);
  if (token != end) lex.fail("expected " + end + ", got " + quoted(token));
}

// Skips an unknown section up to its "$End<name>".
void skip_section(Lexer& lex, std::string_view name) {
  const std::string end = "$End" + std::string(name);
  const int start = lex.line();
  std::string_view token;
  while (lex.next(token))
    if (token == end) return;
  lex.fail_at(start, "section $" + std::string(name) + " is not closed by " + end);
}

// The section name of a "$Name" token.
std::string_view section_name(Lexer& lex, std::string_view token) {
  if (token.size() < 2 || token[0] != '$') lex.fail("expected a section such as $Nodes, got " + quoted(token));
  return token.substr(1);
}

}  // namespace

TetMesh read_gmsh(const fs::path& file, int64_t max_nodes) {
  Lexer lex(read_text(file, "gmsh mesh"), file.string(), false);
  RawMesh raw;
  NodeTags tags;
  std::vector<GmshTet> tets;
  std::vector<GmshTriangle> triangles;
  EntityPhysicals entity_physicals;
  GmshVersion version = GmshVersion::none;
  bool nodes_seen = false, elements_seen = false, names_seen = false, entities_seen = false;
  std::string_view token;
  while (lex.next(token)) {
    if (version == GmshVersion::none && token != "$MeshFormat")
      lex.fail("the file must start with $MeshFormat (is it a gmsh .msh file?), got " + quoted(token));
    const std::string_view name = section_name(lex, token);
    if (name == "MeshFormat") {
      if (version != GmshVersion::none) lex.fail("a second $MeshFormat section");
      version = read_mesh_format(lex);
    } else if (name == "Nodes") {
      if (nodes_seen) lex.fail("a second $Nodes section");
      nodes_seen = true;
      if (version == GmshVersion::v41) read_nodes_v41(lex, raw, tags, max_nodes);
      else read_nodes_v2(lex, raw, tags, max_nodes);
      expect_end(lex, name);
    } else if (name == "Elements") {
      if (elements_seen) lex.fail("a second $Elements section");
      elements_seen = true;
      if (version == GmshVersion::v41) read_elements_v41(lex, raw, tets, triangles);
      else read_elements_v2(lex, raw, tets, triangles);
      expect_end(lex, name);
    } else if (name == "PhysicalNames") {
      if (names_seen) lex.fail("a second $PhysicalNames section");
      names_seen = true;
      read_physical_names(lex, raw);
      expect_end(lex, name);
    } else if (name == "Entities" && version == GmshVersion::v41) {
      if (entities_seen) lex.fail("a second $Entities section");
      entities_seen = true;
      read_entities_v41(lex, entity_physicals);
      expect_end(lex, name);
    } else {
      skip_section(lex, name);
    }
  }
  if (version == GmshVersion::none) throw std::runtime_error(file.string() + ": empty file, expected a gmsh mesh");
  if (!nodes_seen) throw std::runtime_error(file.string() + ": no $Nodes section");
  if (!elements_seen) throw std::runtime_error(file.string() + ": no $Elements section");

  // 4.1: an element's physical groups are its entity's (the first one for a tetrahedron's region).
  auto entity_tags = [&](int dimension, int64_t entity) -> const std::vector<int64_t>* {
    const auto it = entity_physicals.find({dimension, entity});
    return it == entity_physicals.end() ? nullptr : &it->second;
  };
  raw.tets.reserve(tets.size());
  for (const GmshTriangle& t : triangles) {
    std::vector<int64_t> groups;
    if (version == GmshVersion::v41) {
      if (const auto* p = entity_tags(2, t.entity)) groups = *p;
    } else if (t.physical != 0) {
      groups.push_back(t.physical);
    }
    if (groups.empty()) continue;
    std::array<int64_t, 3> nodes;
    for (int a = 0; a < 3; ++a) {
      const auto it = tags.index.find(t.nodes[a]);
      if (it == tags.index.end())
        lex.fail_at(t.line, "triangle " + std::to_string(t.tag) + ": node tag " + std::to_string(t.nodes[a]) +
                                " is not in $Nodes");
      nodes[a] = it->second;
    }
    for (int64_t g : groups) {
      raw.triangles.push_back(nodes);
      raw.triangle_group.push_back(g);
    }
  }
  for (const GmshTet& t : tets) {
    std::array<int64_t, 4> nodes;
    for (int a = 0; a < 4; ++a) {
      const auto it = tags.index.find(t.nodes[a]);
      if (it == tags.index.end())
        lex.fail_at(t.line, "tetrahedron " + std::to_string(t.tag) + ": node tag " + std::to_string(t.nodes[a]) +
                                " is not in $Nodes");
      nodes[a] = it->second;
    }
    raw.tets.push_back(nodes);
    raw.tet_line.push_back(t.line);
    raw.tet_tag.push_back(t.tag);
    int64_t region = t.physical;
    if (version == GmshVersion::v41) {
      const auto* p = entity_tags(3, t.entity);
      region = p && !p->empty() ? p->front() : 0;
    }
    raw.tet_region.push_back(region);
  }
  const std::string none =
      "no 4-node tetrahedra (element type 4) in $Elements, " + std::to_string(raw.ignored_elements) +
      " other elements (a volume mesh of order 1 is needed: gmsh -3 -order 1)";
  return assemble(std::move(raw), file.string(), file.string(), none);
}

fs::path tetgen_element_file(const fs::path& node_file) {
  fs::path ele = node_file;
  return ele.replace_extension(".ele");
}

TetMesh read_tetgen(const fs::path& node_file, int64_t max_nodes) {
  RawMesh raw;
  int64_t base = 0;
  {
    Lexer lex(read_text(node_file, "TetGen .node file"), node_file.string(), true);
    const int64_t count = lex.integer("number of points", 1, kMaxTag);
    if (count > max_nodes)
      lex.fail(std::to_string(count) + " nodes exceed the limit of " + std::to_string(max_nodes));
    const int header_line = lex.line();
    int64_t attributes = 0, markers = 0;
    if (!lex.more_on_line()) lex.fail("the header needs the dimension: \"<points> 3 <attributes> <markers>\"");
    lex.integer("dimension", 3, 3);
    if (lex.more_on_line()) attributes = lex.integer("number of attributes", 0, 1000);
    if (lex.more_on_line()) markers = lex.integer("number of boundary markers", 0, 1);
    lex.end_of_line("the .node header");
    for (int64_t k = 0; k < count; ++k) {
      const int64_t index = lex.integer("point index", -kMaxTag, kMaxTag);
      if (lex.line() == header_line) lex.fail("expected the first point on a new line");
      if (k == 0) {
        if (index != 0 && index != 1) lex.fail("the first point index must be 0 or 1, got " + std::to_string(index));
        base = index;
      } else if (index != base + k) {
        lex.fail("point index " + std::to_string(index) + " where " + std::to_string(base + k) +
                 " was expected (indices must be consecutive)");
      }
      raw.node_tag.push_back(index);
      raw.nodes.push_back(read_xyz(lex));
      raw.node_line.push_back(lex.line());
      for (int64_t a = 0; a < attributes; ++a) lex.real("attribute");
      for (int64_t a = 0; a < markers; ++a) lex.integer("boundary marker", -kMaxTag, kMaxTag);
      lex.end_of_line("a point (index, x, y, z, " + std::to_string(attributes) + " attributes, " +
                      std::to_string(markers) + " markers)");
    }
    std::string_view extra;
    if (lex.next(extra)) lex.fail("unexpected " + quoted(extra) + " after the " + std::to_string(count) + " points");
  }

  const fs::path ele_file = tetgen_element_file(node_file);
  Lexer lex(read_text(ele_file, "TetGen .ele file (the .node file's sibling)"), ele_file.string(), true);
  const int64_t count = lex.integer("number of tetrahedra", 1, kMaxTag);
  const int header_line = lex.line();
  const int64_t per_tet = lex.integer("nodes per tetrahedron", 4, 10);
  if (per_tet != 4 && per_tet != 10) lex.fail("nodes per tetrahedron: must be 4 or 10, got " + std::to_string(per_tet));
  int64_t attributes = 0;
  if (lex.more_on_line()) attributes = lex.integer("number of region attributes", 0, 1000);
  lex.end_of_line("the .ele header");
  const int64_t node_count = static_cast<int64_t>(raw.nodes.size());
  raw.mid_edge.assign(raw.nodes.size(), 0);
  for (int64_t k = 0; k < count; ++k) {
    const int64_t tag = lex.integer("tetrahedron index", -kMaxTag, kMaxTag);
    if (lex.line() == header_line) lex.fail("expected the first tetrahedron on a new line");
    std::array<int64_t, 4> nodes;
    for (int64_t a = 0; a < per_tet; ++a) {
      const int64_t v = lex.integer("node index", -kMaxTag, kMaxTag);
      if (v < base || v >= base + node_count)
        lex.fail("tetrahedron " + std::to_string(tag) + ": node index " + std::to_string(v) + " is out of range [" +
                 std::to_string(base) + ", " + std::to_string(base + node_count - 1) + "]");
      if (a < 4) nodes[a] = v - base;  // a 10-node tetrahedron's corners come first
      else raw.mid_edge[v - base] = 1;
    }
    int64_t region = 0;
    for (int64_t a = 0; a < attributes; ++a) {
      const double value = lex.real("region attribute");
      if (a == 0) region = std::llround(value);
    }
    raw.tet_region.push_back(region);
    raw.tets.push_back(nodes);
    raw.tet_line.push_back(lex.line());
    raw.tet_tag.push_back(tag);
    lex.end_of_line("a tetrahedron (index, " + std::to_string(per_tet) + " nodes, " + std::to_string(attributes) +
                    " attributes)");
  }
  std::string_view extra;
  if (lex.next(extra)) lex.fail("unexpected " + quoted(extra) + " after the " + std::to_string(count) + " tetrahedra");
  return assemble(std::move(raw), node_file.string(), ele_file.string(), "no tetrahedra");
}

int64_t physical_group_tag(const TetMesh& mesh, const fs::path& file, int dimension, std::string_view name) {
  std::string known;
  for (const PhysicalName& p : mesh.physical_names) {
    if (p.dimension != dimension) continue;
    if (p.name == name) return p.tag;
    known += (known.empty() ? "" : ", ") + quoted(std::string_view(p.name));
  }
  throw std::runtime_error(file.string() + ": no physical group of dimension " + std::to_string(dimension) + " is named " +
                           quoted(name) + " (" + (known.empty() ? "the file names none of that dimension" : "the file names " + known) +
                           ")");
}

const std::vector<int>& surface_group_nodes(const TetMesh& mesh, const fs::path& file, std::string_view name) {
  const int64_t tag = physical_group_tag(mesh, file, 2, name);
  for (const SurfaceGroup& g : mesh.surface_groups)
    if (g.tag == tag) return g.nodes;
  static const std::vector<int> none;
  return none;
}

bool known_mesh_extension(const fs::path& file) {
  const std::string ext = file.extension().string();
  return ext == ".msh" || ext == ".node";
}

TetMesh read_mesh(const fs::path& file, int64_t max_nodes) {
  const std::string ext = file.extension().string();
  if (ext == ".msh") return read_gmsh(file, max_nodes);
  if (ext == ".node") return read_tetgen(file, max_nodes);
  throw std::runtime_error(file.string() + ": unknown mesh format '" + ext +
                           "' (known: .msh, gmsh 4.1 or 2.2 ASCII; .node with its .ele, TetGen)");
}

int64_t declared_mesh_nodes(const fs::path& file) {
  const std::string ext = file.extension().string();
  if (ext == ".node") {
    Lexer lex(read_text(file, "TetGen .node file"), file.string(), true);
    return lex.integer("number of points", 1, kMaxTag);
  }
  if (ext != ".msh")
    throw std::runtime_error(file.string() + ": unknown mesh format '" + ext + "' (known: .msh, .node)");
  Lexer lex(read_text(file, "gmsh mesh"), file.string(), false);
  GmshVersion version = GmshVersion::none;
  std::string_view token;
  while (lex.next(token)) {
    if (version == GmshVersion::none && token != "$MeshFormat")
      lex.fail("the file must start with $MeshFormat (is it a gmsh .msh file?), got " + quoted(token));
    const std::string_view name = section_name(lex, token);
    if (name == "MeshFormat") {
      if (version != GmshVersion::none) lex.fail("a second $MeshFormat section");
      version = read_mesh_format(lex);
    } else if (name == "Nodes") {
      if (version == GmshVersion::v2) return lex.integer("number-of-nodes", 0, kMaxTag);
      lex.integer("numEntityBlocks", 0, kMaxTag);
      return lex.integer("numNodes", 0, kMaxTag);
    } else {
      skip_section(lex, name);
    }
  }
  throw std::runtime_error(file.string() + ": no $Nodes section");
}

}  // namespace palpate
