// TetGen .node and .ele files (mesh_reader.h): the points and the tetrahedra read into a raw
// mesh (mesh_parse.h), then assembled.
#include <array>
#include <cmath>
#include <string>
#include <string_view>

#include "core/mesh_parse.h"

namespace palpate {

namespace fs = std::filesystem;

using namespace mesh_io;

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

namespace mesh_io {

int64_t declared_tetgen_nodes(const fs::path& node_file) {
  Lexer lex(read_text(node_file, "TetGen .node file"), node_file.string(), true);
  return lex.integer("number of points", 1, kMaxTag);
}

}  // namespace mesh_io

}  // namespace palpate
