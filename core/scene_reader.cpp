// The scene reader's JSON helpers (scene_reader.h): message formatting, JSON pointers, and
// the JSON text and its overrides.
#include "core/scene_reader.h"

#include <algorithm>
#include <charconv>
#include <system_error>

namespace palpate::scene_io {

// "string \"NaN\"", "number 3.5", "array of 2 elements", "object", "null".
std::string describe(const json& v) {
  std::string s = v.type_name();
  if (v.is_array()) return s + " of " + std::to_string(v.size()) + (v.size() == 1 ? " element" : " elements");
  if (v.is_primitive() && !v.is_null()) {
    std::string text = v.dump(-1, ' ', false, json::error_handler_t::replace);  // a bare override may be bad UTF-8
    if (text.size() > 40) text = text.substr(0, 37) + "...";
    s += " " + text;
  }
  return s;
}

// One reference token of a JSON pointer (RFC 6901: '~' -> "~0", '/' -> "~1").
std::string pointer_token(std::string_view key) {
  std::string out;
  for (char c : key) {
    if (c == '~') out += "~0";
    else if (c == '/') out += "~1";
    else out += c;
  }
  return out;
}

// True if `path` is `root` or lies below it.
bool within(const std::string& path, const std::string& root) {
  return path.compare(0, root.size(), root) == 0 && (path.size() == root.size() || path[root.size()] == '/');
}

// ---------------------------------------------------------------------------
// JSON text and overrides.

namespace {

// nlohmann's message without its "[json.exception.x.nnn] " tag and its own position
// ("parse error at line 3, column 0: "), whose column is unreliable.
std::string json_message(const nlohmann::json::exception& e) {
  std::string m = e.what();
  if (const auto tag = m.find("] "); m.rfind("[json.exception.", 0) == 0 && tag != std::string::npos)
    m.erase(0, tag + 2);
  if (m.rfind("parse error", 0) == 0)
    if (const auto colon = m.find(": "); colon != std::string::npos) m.erase(0, colon + 2);
  return m;
}

// Line and column (1-based, columns in bytes) of the 1-based byte position `byte`.
std::string line_column(const std::string& text, std::size_t byte) {
  const std::size_t end = std::min(byte == 0 ? 0 : byte - 1, text.size());  // characters before it
  std::size_t line = 1, line_start = 0;
  for (std::size_t i = 0; i < end; ++i)
    if (text[i] == '\n') ++line, line_start = i + 1;
  return "line " + std::to_string(line) + ", column " + std::to_string(end - line_start + 1);
}

}  // namespace

json parse_json(const std::string& text, const std::string& source) {
  try {
    return json::parse(text);
  } catch (const json::parse_error& e) {
    throw SceneError(source, "", "invalid JSON at " + line_column(text, e.byte) + ": " + json_message(e));
  } catch (const json::exception& e) {  // number overflow "... parsing '1e400'": no position given
    const std::string message = json_message(e);
    std::string where;
    if (const auto open = message.find('\''), close = message.rfind('\''); open < close && close != std::string::npos)
      if (const auto at = text.find(message.substr(open + 1, close - open - 1)); at != std::string::npos)
        where = " at " + line_column(text, at + 1);
    throw SceneError(source, "", "invalid JSON" + where + ": " + message);
  }
}

namespace {

// A JSON literal if the text is one ("12", "[0,0,1]", "\"x\"", "true"), else the bare string.
json override_value(const std::string& text) {
  try {
    json v = json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (!v.is_discarded()) return v;
  } catch (const json::exception&) {
  }
  return text;
}

// The array index a key token names ("2"), or SIZE_MAX.
std::size_t array_index(const std::string& token) {
  std::size_t i = 0;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), i);
  return ec == std::errc() && end == token.data() + token.size() ? i : std::numeric_limits<std::size_t>::max();
}

}  // namespace

// Sets root at the dotted `key` (creating missing objects); returns the JSON pointer it set.
std::string apply_override(json& root, const std::string& key, const std::string& value, const std::string& source) {
  const std::string src = Origin::override_source(source, key + "=" + value);
  std::vector<std::string> tokens;
  for (std::size_t start = 0;;) {
    const std::size_t dot = key.find('.', start);
    tokens.push_back(key.substr(start, dot == std::string::npos ? std::string::npos : dot - start));
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  for (const auto& t : tokens)
    if (t.empty()) throw SceneError(src, "", "override key must be a dotted field path such as body.distribution.per_edge");

  json* node = &root;
  std::string path;
  for (const auto& t : tokens) {
    if (node->is_null()) *node = json::object();  // a missing intermediate object
    if (node->is_object()) {
      node = &(*node)[t];
    } else if (const std::size_t i = array_index(t); node->is_array() && i < node->size()) {
      node = &(*node)[i];
    } else {
      throw SceneError(src, path, "cannot set '" + t + "' in " + describe(*node) + " (override " + key + ")");
    }
    path.push_back('/');
    path += pointer_token(t);
  }
  *node = override_value(value);
  return path;
}

}  // namespace palpate::scene_io
