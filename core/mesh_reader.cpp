// Tetrahedral mesh files -> node positions, tetrahedra and nodal volumes (mesh_reader.h).
//
// The readers: mesh_gmsh.cpp (gmsh .msh) and mesh_tetgen.cpp (TetGen .node/.ele), both
// through the tokenizer of mesh_parse.h; mesh_assembly.cpp checks what they read and derives
// the volumes, the boundary faces and the surface groups (the rules in mesh_reader.h). Here:
// the choice of reader by extension, the physical groups' look-up, and the helpers of messages.
#include "core/mesh_reader.h"

#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <string_view>

#include "core/mesh_parse.h"

namespace palpate {

namespace fs = std::filesystem;

namespace mesh_io {

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

}  // namespace mesh_io

using namespace mesh_io;

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
  if (ext == ".node") return declared_tetgen_nodes(file);
  if (ext != ".msh")
    throw std::runtime_error(file.string() + ": unknown mesh format '" + ext + "' (known: .msh, .node)");
  return declared_gmsh_nodes(file);
}

}  // namespace palpate
