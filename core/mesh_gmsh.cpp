// gmsh .msh files, 4.1 and 2.2 ASCII (mesh_reader.h): the sections read into a raw mesh
// (mesh_parse.h), the node tags and physical groups resolved, then assembled.
#include <array>
#include <map>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/mesh_parse.h"

namespace palpate {

namespace fs = std::filesystem;

using namespace mesh_io;

namespace {

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

namespace mesh_io {

int64_t declared_gmsh_nodes(const fs::path& file) {
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

}  // namespace mesh_io

}  // namespace palpate
