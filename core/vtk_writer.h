#pragma once
// VTK XML files for ParaView, with no dependency: an unstructured grid (.vtu) from plain
// arrays (points, cells, named point-data arrays, field data) and a collection (.pvd) that
// makes a time series of them, with several parts per time step.
//
// Formats (VTK's "VTK XML File Formats"): `ascii` writes the numbers as text; `binary` is
// VTK's inline base64 form: per array, base64 of [UInt64 byte count][the raw little-endian
// values], one base64 run for the two (header_type="UInt64", no compression). ParaView and
// VTK's readers take both; binary is about 3x smaller and exact (ascii is written with
// 17 significant digits, so it is exact too, only larger).
//
//   vtk::UnstructuredGrid g;
//   g.points = ...;                      // 3 per point
//   vtk::add_cells(g, vtk::CellType::tetra, connectivity);
//   g.point_data.push_back({"displacement", 3, values});
//   vtk::write_vtu("out/step_0.vtu", g, vtk::Encoding::binary);
//   vtk::write_pvd("out/series.pvd", {{0.0, 0, "step_0.vtu"}, ...});
//
// No networking, no threads, no JSON: core (tests/dependency_direction.cmake). Errors (a
// file that cannot be written, inconsistent arrays) are std::runtime_error naming the file
// and what is wrong.
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/model.h"
#include "core/node_cloud.h"
#include "core/state.h"
#include "core/types.h"

namespace palpate::vtk {

// VTK's cell type numbers.
enum class CellType : uint8_t { vertex = 1, triangle = 5, tetra = 10, hexahedron = 12 };
// Nodes of a cell of the type.
int nodes_per_cell(CellType type);

enum class Encoding { ascii, binary };

// A named array of `components` values per tuple (point data: one tuple per point;
// field data: any number of tuples). Written as Float64.
struct DataArray {
  std::string name;
  int components = 1;
  std::vector<double> values;  // tuples x components
};

struct UnstructuredGrid {
  std::vector<double> points;          // 3 per point, m
  std::vector<int64_t> connectivity;   // the cells' point indices, one cell after the other
  std::vector<int64_t> offsets;        // per cell: the end of its points in connectivity
  std::vector<uint8_t> types;          // per cell: its CellType
  std::vector<DataArray> point_data;   // one tuple per point each
  std::vector<DataArray> field_data;   // whole-dataset values (the tool's position and force)
  int64_t point_count() const { return static_cast<int64_t>(points.size() / 3); }
};

// Appends cells of one type, nodes_per_cell(type) indices each (connectivity.size() must be a
// multiple of it).
void add_cells(UnstructuredGrid& grid, CellType type, const std::vector<int64_t>& connectivity);
// One VTK_VERTEX per point: a cloud without connectivity (ParaView draws the points).
void add_vertex_cells(UnstructuredGrid& grid);

// Checks the grid (3 values per point, cell indices in range, offsets ascending and
// matching the types, point data with one tuple per point, finite values) and writes it.
// Throws std::runtime_error naming the file and the first problem.
void write_vtu(const std::filesystem::path& file, const UnstructuredGrid& grid, Encoding encoding);

// One dataset of a collection: `file` relative to the .pvd's folder (as ParaView resolves it).
struct CollectionEntry {
  double time = 0.0;
  int part = 0;  // several parts at one time: e.g. 0 = the body, 1 = the tool
  std::string file;
};
void write_pvd(const std::filesystem::path& file, const std::vector<CollectionEntry>& entries);

// --- Building blocks for palpate's models ------------------------------------------

// The cells of a node cloud (core/node_cloud.h): a tetrahedral mesh's tetrahedra (VTK_TETRA),
// a lattice's (grid, jittered, graded; lattice_size.prod() == n, node a + nx (b + ny c) as the
// hex FEM numbers them) bricks as VTK_HEXAHEDRON in VTK's node order (the hex FEM's local
// order, core/hex_fem.h), else one VTK_VERTEX per point (a node list).
void add_cloud_cells(UnstructuredGrid& grid, const NodeCloud& cloud);

// The body at a state, for ParaView: a copy of `cells` (a grid holding only the body's cells,
// add_cloud_cells) with the points at state.position and the point data
//   "displacement"            3, m   x - X
//   "displacement_magnitude"  1, m   |x - X|
//   "von_mises"               1, Pa  von Mises of the Cauchy stress (core/stress.h)
//   "contact_force"           3, N   the tool's force on the particle, zero off contact
// and the field data "time" (s), "tick", "tool_position" (m), "tool_contact_force" (N, of the
// body on the tool) and "force_command" (N, the force on the tool in force mode).
UnstructuredGrid body_state_grid(const UnstructuredGrid& cells, const Model& model, const State& state);

// A sphere's surface as triangles (an icosahedron subdivided `subdivisions` times and
// projected on the sphere: 10 4^s + 2 points, 20 4^s triangles, counterclockwise seen from
// outside), with point data "Normals" (unit outward normals, for smooth shading).
UnstructuredGrid sphere_surface(const Vec3& centre, double radius, int subdivisions = 3);

// Decodes base64 (for the readers of tests and tools; whitespace skipped). Throws
// std::runtime_error on a character outside the alphabet.
std::vector<uint8_t> base64_decode(const std::string& text);
std::string base64_encode(const uint8_t* data, size_t size);

}  // namespace palpate::vtk
