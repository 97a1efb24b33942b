#include "core/vtk_writer.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

#include "core/stress.h"

namespace palpate::vtk {

static_assert(std::endian::native == std::endian::little, "the binary VTK files are written little-endian");

int nodes_per_cell(CellType type) {
  switch (type) {
    case CellType::vertex: return 1;
    case CellType::triangle: return 3;
    case CellType::tetra: return 4;
    case CellType::hexahedron: return 8;
  }
  return 0;
}

void add_cells(UnstructuredGrid& grid, CellType type, const std::vector<int64_t>& connectivity) {
  const size_t k = static_cast<size_t>(nodes_per_cell(type));
  if (connectivity.size() % k != 0)
    throw std::runtime_error("vtk::add_cells: " + std::to_string(connectivity.size()) +
                             " indices are not a whole number of cells of " + std::to_string(k) + " points");
  for (size_t c = 0; c < connectivity.size(); c += k) {
    grid.connectivity.insert(grid.connectivity.end(), connectivity.begin() + c, connectivity.begin() + c + k);
    grid.offsets.push_back(static_cast<int64_t>(grid.connectivity.size()));
    grid.types.push_back(static_cast<uint8_t>(type));
  }
}

void add_vertex_cells(UnstructuredGrid& grid) {
  std::vector<int64_t> all(static_cast<size_t>(grid.point_count()));
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int64_t>(i);
  add_cells(grid, CellType::vertex, all);
}

// ---------------------------------------------------------------------------
// base64 (RFC 4648, with '=' padding)

namespace {
constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
}

std::string base64_encode(const uint8_t* data, size_t size) {
  std::string out;
  out.reserve((size + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 3 <= size; i += 3) {
    const uint32_t v = (uint32_t{data[i]} << 16) | (uint32_t{data[i + 1]} << 8) | data[i + 2];
    for (int s = 18; s >= 0; s -= 6) out.push_back(kAlphabet[(v >> s) & 63]);
  }
  if (const size_t rest = size - i; rest > 0) {
    const uint32_t v = (uint32_t{data[i]} << 16) | (rest > 1 ? uint32_t{data[i + 1]} << 8 : 0u);
    out.push_back(kAlphabet[(v >> 18) & 63]);
    out.push_back(kAlphabet[(v >> 12) & 63]);
    out.push_back(rest > 1 ? kAlphabet[(v >> 6) & 63] : '=');
    out.push_back('=');
  }
  return out;
}

std::vector<uint8_t> base64_decode(const std::string& text) {
  std::vector<uint8_t> out;
  out.reserve(text.size() / 4 * 3);
  uint32_t v = 0;
  int bits = 0;
  for (const char c : text) {
    if (c == ' ' || c == '\n' || c == '\r' || c == '\t') continue;
    if (c == '=') {  // padding: the group ends here
      v = 0;
      bits = 0;
      continue;
    }
    const char* at = std::strchr(kAlphabet, c);
    if (at == nullptr || c == '\0')
      throw std::runtime_error(std::string("base64: '") + c + "' is not a base64 character");
    v = (v << 6) | static_cast<uint32_t>(at - kAlphabet);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<uint8_t>((v >> bits) & 0xff));
    }
  }
  return out;
}

// ---------------------------------------------------------------------------
// Writing

namespace {

[[noreturn]] void fail(const std::filesystem::path& file, const std::string& what) {
  throw std::runtime_error(file.string() + ": " + what);
}

// A DataArray element's text. `type` is the VTK type name of T.
// tuples >= 0 writes NumberOfTuples (field data: VTK's reader needs it there).
template <class T>
void write_array(std::ostream& out, const char* type, const std::string& name, int components, const T* values,
                 size_t count, Encoding encoding, const char* indent, int64_t tuples = -1) {
  out << indent << "<DataArray type=\"" << type << "\"";
  if (!name.empty()) out << " Name=\"" << name << "\"";
  if (components != 1) out << " NumberOfComponents=\"" << components << "\"";
  if (tuples >= 0) out << " NumberOfTuples=\"" << tuples << "\"";
  out << " format=\"" << (encoding == Encoding::binary ? "binary" : "ascii") << "\">\n" << indent << "  ";
  if (encoding == Encoding::binary) {
    // One base64 run of [UInt64 byte count][values] (header_type="UInt64", uncompressed).
    const uint64_t bytes = count * sizeof(T);
    std::vector<uint8_t> raw(sizeof bytes + bytes);
    std::memcpy(raw.data(), &bytes, sizeof bytes);
    if (bytes > 0) std::memcpy(raw.data() + sizeof bytes, values, bytes);
    out << base64_encode(raw.data(), raw.size());
  } else {
    for (size_t k = 0; k < count; ++k) {
      if (k > 0 && k % 9 == 0) out << "\n" << indent << "  ";
      else if (k > 0) out << ' ';
      if constexpr (std::is_same_v<T, uint8_t>) out << static_cast<int>(values[k]);
      else out << values[k];
    }
  }
  out << "\n" << indent << "</DataArray>\n";
}

// A name VTK's XML parser takes as an attribute value.
void check_name(const std::filesystem::path& file, const std::string& name) {
  if (name.empty()) fail(file, "a data array without a name");
  for (const char c : name)
    if (c == '"' || c == '<' || c == '>' || c == '&' || static_cast<unsigned char>(c) < 32)
      fail(file, "data array name '" + name + "': no quotes, angle brackets, ampersands or control characters");
}

void check_values(const std::filesystem::path& file, const DataArray& a, size_t tuples, bool fixed_tuples) {
  check_name(file, a.name);
  if (a.components < 1) fail(file, "data array '" + a.name + "': components must be >= 1");
  if (a.values.size() % static_cast<size_t>(a.components) != 0)
    fail(file, "data array '" + a.name + "': " + std::to_string(a.values.size()) + " values are not a whole number of " +
                   std::to_string(a.components) + "-component tuples");
  if (fixed_tuples && a.values.size() != tuples * static_cast<size_t>(a.components))
    fail(file, "point data '" + a.name + "': " + std::to_string(a.values.size() / a.components) + " tuples for " +
                   std::to_string(tuples) + " points");
  for (size_t k = 0; k < a.values.size(); ++k)
    if (!std::isfinite(a.values[k]))
      fail(file, "data array '" + a.name + "': value " + std::to_string(k) + " is not finite");
}

void check_grid(const std::filesystem::path& file, const UnstructuredGrid& g) {
  if (g.points.size() % 3 != 0) fail(file, std::to_string(g.points.size()) + " point coordinates: not 3 per point");
  for (size_t k = 0; k < g.points.size(); ++k)
    if (!std::isfinite(g.points[k])) fail(file, "point coordinate " + std::to_string(k) + " is not finite");
  const int64_t n = g.point_count();
  if (g.offsets.size() != g.types.size())
    fail(file, std::to_string(g.offsets.size()) + " cell offsets for " + std::to_string(g.types.size()) + " cell types");
  int64_t begin = 0;
  for (size_t c = 0; c < g.offsets.size(); ++c) {
    const int expected = nodes_per_cell(static_cast<CellType>(g.types[c]));
    if (expected == 0) fail(file, "cell " + std::to_string(c) + ": unknown VTK cell type " + std::to_string(g.types[c]));
    if (g.offsets[c] - begin != expected)
      fail(file, "cell " + std::to_string(c) + ": " + std::to_string(g.offsets[c] - begin) + " points for a cell of type " +
                     std::to_string(g.types[c]) + " (" + std::to_string(expected) + ")");
    begin = g.offsets[c];
  }
  if (begin != static_cast<int64_t>(g.connectivity.size()))
    fail(file, "the last cell offset " + std::to_string(begin) + " is not the connectivity's length " +
                   std::to_string(g.connectivity.size()));
  for (size_t k = 0; k < g.connectivity.size(); ++k)
    if (g.connectivity[k] < 0 || g.connectivity[k] >= n)
      fail(file, "cell connectivity " + std::to_string(k) + ": point " + std::to_string(g.connectivity[k]) +
                     " out of range (" + std::to_string(n) + " points)");
  std::map<std::string, int> names;
  for (const DataArray& a : g.point_data) {
    check_values(file, a, static_cast<size_t>(n), true);
    if (names[a.name]++ > 0) fail(file, "two point data arrays named '" + a.name + "'");
  }
  names.clear();
  for (const DataArray& a : g.field_data) {
    check_values(file, a, 0, false);
    if (names[a.name]++ > 0) fail(file, "two field data arrays named '" + a.name + "'");
  }
}

// Writes to file.tmp and renames it, so a reader (ParaView watching the folder) never sees a
// half-written file.
void write_atomically(const std::filesystem::path& file, const std::string& text) {
  std::filesystem::path tmp = file;
  tmp += ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) fail(file, "cannot write (does its folder exist and is it writable?)");
    out << text;
    out.close();
    if (!out) fail(file, "write failed (disk full?)");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) fail(file, "cannot rename " + tmp.string() + " to it: " + ec.message());
}

}  // namespace

void write_vtu(const std::filesystem::path& file, const UnstructuredGrid& g, Encoding encoding) {
  check_grid(file, g);
  std::ostringstream out;
  out.precision(17);  // doubles round-trip exactly through text
  out << "<?xml version=\"1.0\"?>\n"
      << "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
      << "  <UnstructuredGrid>\n";
  if (!g.field_data.empty()) {
    out << "    <FieldData>\n";
    for (const DataArray& a : g.field_data)
      write_array(out, "Float64", a.name, a.components, a.values.data(), a.values.size(), encoding, "      ",
                  static_cast<int64_t>(a.values.size() / a.components));
    out << "    </FieldData>\n";
  }
  out << "    <Piece NumberOfPoints=\"" << g.point_count() << "\" NumberOfCells=\"" << g.types.size() << "\">\n";
  if (!g.point_data.empty()) {
    out << "      <PointData";
    for (const DataArray& a : g.point_data)  // the first scalar and vector arrays are the active ones
      if (a.components == 1) {
        out << " Scalars=\"" << a.name << "\"";
        break;
      }
    for (const DataArray& a : g.point_data)
      if (a.components == 3 && a.name != "Normals") {
        out << " Vectors=\"" << a.name << "\"";
        break;
      }
    for (const DataArray& a : g.point_data)
      if (a.components == 3 && a.name == "Normals") out << " Normals=\"Normals\"";
    out << ">\n";
    for (const DataArray& a : g.point_data)
      write_array(out, "Float64", a.name, a.components, a.values.data(), a.values.size(), encoding, "        ");
    out << "      </PointData>\n";
  }
  out << "      <Points>\n";
  write_array(out, "Float64", "Points", 3, g.points.data(), g.points.size(), encoding, "        ");
  out << "      </Points>\n      <Cells>\n";
  write_array(out, "Int64", "connectivity", 1, g.connectivity.data(), g.connectivity.size(), encoding, "        ");
  write_array(out, "Int64", "offsets", 1, g.offsets.data(), g.offsets.size(), encoding, "        ");
  write_array(out, "UInt8", "types", 1, g.types.data(), g.types.size(), encoding, "        ");
  out << "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n";
  write_atomically(file, out.str());
}

void write_pvd(const std::filesystem::path& file, const std::vector<CollectionEntry>& entries) {
  std::ostringstream out;
  out.precision(17);
  out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"1.0\" byte_order=\"LittleEndian\">\n"
      << "  <Collection>\n";
  for (const CollectionEntry& e : entries) {
    if (!std::isfinite(e.time)) fail(file, "entry '" + e.file + "': time is not finite");
    if (e.file.empty() || e.file.find('"') != std::string::npos || e.file.find('<') != std::string::npos ||
        e.file.find('&') != std::string::npos)
      fail(file, "entry file name '" + e.file + "': empty, or with a quote, '<' or '&'");
    out << "    <DataSet timestep=\"" << e.time << "\" group=\"\" part=\"" << e.part << "\" file=\"" << e.file
        << "\"/>\n";
  }
  out << "  </Collection>\n</VTKFile>\n";
  write_atomically(file, out.str());
}

// ---------------------------------------------------------------------------
// Cells of palpate's clouds, the tool's sphere

void add_cloud_cells(UnstructuredGrid& grid, const NodeCloud& cloud) {
  const int64_t n = cloud.positions.cols();
  if (grid.point_count() != n)
    throw std::runtime_error("vtk::add_cloud_cells: the grid has " + std::to_string(grid.point_count()) +
                             " points, the cloud " + std::to_string(n));
  if (!cloud.tetrahedra.empty()) {
    std::vector<int64_t> c;
    c.reserve(4 * cloud.tetrahedra.size());
    for (const auto& t : cloud.tetrahedra) c.insert(c.end(), t.begin(), t.end());
    add_cells(grid, CellType::tetra, c);
    return;
  }
  const Eigen::Vector3i s = cloud.lattice_size;
  if (s.minCoeff() >= 2 && static_cast<int64_t>(s[0]) * s[1] * s[2] == n) {
    // Bricks in the hex FEM's local order (core/hex_fem.h), which is VTK_HEXAHEDRON's:
    // (0,0,0) (1,0,0) (1,1,0) (0,1,0), then the same at the upper z.
    auto node = [&](int a, int b, int c) { return static_cast<int64_t>(a) + s[0] * (b + static_cast<int64_t>(s[1]) * c); };
    std::vector<int64_t> c;
    c.reserve(8 * static_cast<size_t>(s[0] - 1) * (s[1] - 1) * (s[2] - 1));
    for (int k = 0; k + 1 < s[2]; ++k)
      for (int j = 0; j + 1 < s[1]; ++j)
        for (int i = 0; i + 1 < s[0]; ++i)
          for (const int64_t v : {node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                                  node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1)})
            c.push_back(v);
    add_cells(grid, CellType::hexahedron, c);
    return;
  }
  add_vertex_cells(grid);
}

UnstructuredGrid body_state_grid(const UnstructuredGrid& cells, const Model& model, const State& state) {
  const int n = model.particle_count;
  UnstructuredGrid g = cells;
  if (g.point_count() != 0 && g.point_count() != n)
    throw std::runtime_error("vtk::body_state_grid: the cells are for " + std::to_string(g.point_count()) +
                             " points, the model has " + std::to_string(n));
  g.points.assign(state.position.data(), state.position.data() + 3 * static_cast<size_t>(n));
  DataArray displacement{"displacement", 3, {}}, magnitude{"displacement_magnitude", 1, {}};
  displacement.values.reserve(3 * static_cast<size_t>(n));
  magnitude.values.reserve(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    const Vec3 u = state.position.col(i) - model.rest_position.col(i);
    displacement.values.insert(displacement.values.end(), {u[0], u[1], u[2]});
    magnitude.values.push_back(u.norm());
  }
  DataArray von_mises{"von_mises", 1, {}};
  von_mises_stress(model, state.position, von_mises.values);
  DataArray contact{"contact_force", 3, std::vector<double>(3 * static_cast<size_t>(n), 0.0)};
  for (size_t c = 0; c < state.contact_index.size(); ++c)
    for (int a = 0; a < 3; ++a) contact.values[3 * static_cast<size_t>(state.contact_index[c]) + a] = state.contact_force(a, c);
  g.point_data = {std::move(displacement), std::move(magnitude), std::move(von_mises), std::move(contact)};
  const Vec3& c = state.indenter_center;
  const Vec3& f = state.indenter_contact_force;
  const Vec3& command = state.force_command;
  g.field_data = {{"time", 1, {state.time}},
                  {"tick", 1, {static_cast<double>(state.tick)}},
                  {"tool_position", 3, {c[0], c[1], c[2]}},
                  {"tool_contact_force", 3, {f[0], f[1], f[2]}},
                  {"force_command", 3, {command[0], command[1], command[2]}}};
  return g;
}

UnstructuredGrid sphere_surface(const Vec3& centre, double radius, int subdivisions) {
  // The icosahedron: (0, +-1, +-t) cyclically, t the golden ratio.
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3> p = {{-1, t, 0}, {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3& v : p) v.normalize();
  std::vector<std::array<int, 3>> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                       {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                       {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                       {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> midpoint;
    auto middle = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      const auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      p.push_back((p[a] + p[b]).normalized());
      return midpoint[key] = static_cast<int>(p.size()) - 1;
    };
    std::vector<std::array<int, 3>> finer;
    finer.reserve(4 * f.size());
    for (const auto& tri : f) {
      const int ab = middle(tri[0], tri[1]), bc = middle(tri[1], tri[2]), ca = middle(tri[2], tri[0]);
      finer.push_back({tri[0], ab, ca});
      finer.push_back({tri[1], bc, ab});
      finer.push_back({tri[2], ca, bc});
      finer.push_back({ab, bc, ca});
    }
    f = std::move(finer);
  }
  UnstructuredGrid g;
  DataArray normals{"Normals", 3, {}};
  for (const Vec3& v : p) {
    const Vec3 x = centre + radius * v;
    g.points.insert(g.points.end(), {x[0], x[1], x[2]});
    normals.values.insert(normals.values.end(), {v[0], v[1], v[2]});
  }
  std::vector<int64_t> c;
  for (const auto& tri : f) {
    // Counterclockwise seen from outside: the normal (b - a) x (c - a) points away from the centre.
    const Vec3 n = (p[tri[1]] - p[tri[0]]).cross(p[tri[2]] - p[tri[0]]);
    if (n.dot(p[tri[0]]) >= 0) c.insert(c.end(), {tri[0], tri[1], tri[2]});
    else c.insert(c.end(), {tri[0], tri[2], tri[1]});
  }
  add_cells(g, CellType::triangle, c);
  g.point_data.push_back(std::move(normals));
  return g;
}

}  // namespace palpate::vtk
