// libFuzzer target: the tetrahedral mesh readers (core/mesh_reader.h). The first
// byte picks the format: even = gmsh .msh (the rest of the input is the file), odd
// = TetGen (the rest is the .node text, a NUL byte, then the .ele text). The input
// is written to private temporary files (the readers take paths). The contract: a
// mesh whose positions are finite, whose tetrahedra index its nodes and are
// positively oriented, whose nodes are all used, whose nodal volumes are positive
// and sum to its volume, whose header declares at least its nodes, and whose
// physical names are well formed, unique and found by physical_group_tag; or a
// std::runtime_error. The seeds (corpus/mesh_reader_fuzz/) include a mesh for each
// refusal of the checks: inverted, degenerate, unused node, two parts, a pinch,
// an overlap, duplicate physical names; and physical surface groups (4.1 through
// $Entities, 2.2 through element tags) and TetGen region attributes.
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "core/mesh_reader.h"

namespace {

// Files in one private folder per process, rewritten for every input, removed at exit.
struct TempDir {
  TempDir() {
    const char* dir = std::getenv("TMPDIR");
    path = std::string(dir && *dir ? dir : "/tmp") + "/palpate-mesh-fuzz-XXXXXX";
    if (!mkdtemp(path.data())) std::abort();
  }
  ~TempDir() {
    for (const char* name : {"/m.msh", "/m.node", "/m.ele"}) unlink((path + name).c_str());
    rmdir(path.c_str());
  }
  std::string file(const char* name) const { return path + name; }
  std::string path;
};

void write(const std::string& file, std::string_view text) {
  std::FILE* f = std::fopen(file.c_str(), "wb");
  if (!f) std::abort();
  if (!text.empty() && std::fwrite(text.data(), 1, text.size(), f) != text.size()) std::abort();
  std::fclose(f);
}

// The promised result (aborts otherwise).
void check(const palpate::TetMesh& m, int64_t declared) {
  const int64_t n = m.positions.cols();
  if (n < 4 || m.tetrahedra.empty() || !m.positions.allFinite() || m.unused_nodes < 0) std::abort();
  if (static_cast<int64_t>(m.nodal_volume.size()) != n || declared < n + m.unused_nodes) std::abort();
  double sum = 0;
  for (double v : m.nodal_volume) {
    if (!(v > 0)) std::abort();
    sum += v;
  }
  for (const auto& t : m.tetrahedra) {
    for (int v : t)
      if (v < 0 || v >= n) std::abort();
    const palpate::Vec3 a = m.positions.col(t[0]);
    const double V = (m.positions.col(t[1]) - a).dot((m.positions.col(t[2]) - a).cross(m.positions.col(t[3]) - a));
    if (!(V > 0)) std::abort();
  }
  if (!(std::abs(sum - m.total_volume) <= 1e-9 * m.total_volume)) std::abort();
  // Every kept node is a corner of some tetrahedron.
  std::vector<char> used(n, 0);
  for (const auto& t : m.tetrahedra)
    for (int v : t) used[v] = 1;
  for (char u : used)
    if (!u) std::abort();
  // A region per tetrahedron; boundary faces index the nodes and are outward (away from
  // the rest of the body: a closed surface encloses the mesh's volume, divergence theorem).
  if (m.tetrahedron_region.size() != m.tetrahedra.size() || m.boundary_faces.size() < 4) std::abort();
  double enclosed = 0;
  const palpate::Vec3 origin = m.positions.col(0);
  const double L = (m.positions.rowwise().maxCoeff() - m.positions.rowwise().minCoeff()).norm();
  for (const auto& f : m.boundary_faces) {
    for (int v : f)
      if (v < 0 || v >= n) std::abort();
    const palpate::Vec3 a = m.positions.col(f[0]) - origin, b = m.positions.col(f[1]) - origin,
                        c = m.positions.col(f[2]) - origin;
    enclosed += (a + b + c).dot((b - a).cross(c - a)) / 18.0;
  }
  const double round_off = 1e-12 * static_cast<double>(m.boundary_faces.size()) * L * L * L;
  if (!(std::abs(enclosed - m.total_volume) <= 1e-6 * m.total_volume + round_off)) std::abort();
  // Surface groups: ascending unique node indices.
  for (const palpate::SurfaceGroup& g : m.surface_groups)
    for (size_t k = 0; k < g.nodes.size(); ++k)
      if (g.nodes[k] < 0 || g.nodes[k] >= n || (k > 0 && g.nodes[k] <= g.nodes[k - 1])) std::abort();
}

// The names: dimension 0..3, tag >= 1, non-empty, each (dimension, name) found.
void check_names(const palpate::TetMesh& m, const std::string& file) {
  for (const palpate::PhysicalName& p : m.physical_names) {
    if (p.dimension < 0 || p.dimension > 3 || p.tag < 1 || p.name.empty() || p.line < 1) std::abort();
    try {
      if (palpate::physical_group_tag(m, file, p.dimension, p.name) != p.tag) std::abort();
    } catch (const std::runtime_error&) {
      std::abort();
    }
  }
  // A name no group can have (names end at a double quote) is refused.
  try {
    palpate::physical_group_tag(m, file, 2, "no \"such\" group");
    std::abort();
  } catch (const std::runtime_error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static TempDir dir;
  if (size == 0) return 0;
  const bool tetgen = data[0] & 1;
  const std::string_view rest(reinterpret_cast<const char*>(data) + 1, size - 1);
  std::string file;
  if (tetgen) {
    const size_t split = rest.find('\0');
    write(dir.file("/m.node"), rest.substr(0, split));
    write(dir.file("/m.ele"), split == std::string_view::npos ? std::string_view() : rest.substr(split + 1));
    file = dir.file("/m.node");
  } else {
    write(dir.file("/m.msh"), rest);
    file = dir.file("/m.msh");
  }
  constexpr int64_t kMaxNodes = 4096;  // bounded work per input
  palpate::TetMesh mesh;
  try {
    mesh = palpate::read_mesh(file, kMaxNodes);
  } catch (const std::runtime_error&) {
    return 0;
  }
  int64_t declared = -1;
  try {
    declared = palpate::declared_mesh_nodes(file);  // must read the header of a file that was read
  } catch (const std::runtime_error&) {
    std::abort();
  }
  check(mesh, declared);
  check_names(mesh, file);
  return 0;
}
