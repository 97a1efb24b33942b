#pragma once
// Internal to the mesh readers (core/mesh_*.cpp; not installed): what the gmsh and the TetGen
// reader share. One whitespace tokenizer that knows the line of every token (for messages)
// and, for TetGen, skips '#' comments; the raw mesh both collect, node references resolved
// after the whole file is read; and assemble() (mesh_assembly.cpp), which checks the raw mesh
// (the rules in mesh_reader.h) and derives the TetMesh: kept nodes, lumped volumes, boundary
// faces, surface groups.
#include <array>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "core/mesh_reader.h"
#include "core/number_format.h"
#include "core/types.h"

namespace palpate::mesh_io {

// Coordinates beyond this are refused: volumes of larger values could overflow.
inline constexpr double kMaxCoordinate = 1e12;  // m

// The text of a token for a message: at most 40 bytes, control bytes escaped.
std::string quoted(std::string_view token);

// The whole of `file`; `what` names it in the message when it cannot be read.
std::string read_text(const std::filesystem::path& file, const char* what);

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
    if (std::abs(value) > kMaxCoordinate) fail(what + ": |" + quoted(t) + "| exceeds " + format_number(kMaxCoordinate));
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

[[noreturn]] inline void fail_at(const std::string& file, int line, const std::string& reason) {
  throw std::runtime_error(file + ":" + std::to_string(line) + ": " + reason);
}

inline constexpr int64_t kMaxTag = std::numeric_limits<int64_t>::max() / 2;

inline Vec3 read_xyz(Lexer& lex) {
  Vec3 p;
  p[0] = lex.real("x");
  p[1] = lex.real("y");
  p[2] = lex.real("z");
  return p;
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

// Checks the tetrahedra, drops mid-edge nodes, lumps the volumes (mesh_assembly.cpp). Messages
// name `node_file` or `element_file` (the same file for gmsh); an empty mesh is refused with
// `what_if_empty`.
TetMesh assemble(RawMesh raw, const std::string& node_file, const std::string& element_file,
                 const std::string& what_if_empty);

// The node count the header declares (declared_mesh_nodes): $Nodes of a gmsh file
// (mesh_gmsh.cpp), the first line of a TetGen .node file (mesh_tetgen.cpp).
int64_t declared_gmsh_nodes(const std::filesystem::path& file);
int64_t declared_tetgen_nodes(const std::filesystem::path& node_file);

}  // namespace palpate::mesh_io
