#pragma once
// Internal to the scene reader (core/scene*.cpp; not installed): a JSON value with its JSON
// pointer, read through accessors that throw a SceneError naming the pointer, the source and
// the reason; the number ranges and the names of enumerated values those messages quote; the
// JSON text and the "key=value" overrides (docs/scene-format.md).
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <iterator>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/number_format.h"
#include "core/scene.h"

namespace palpate::scene_io {

using json = nlohmann::json;

inline constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------
// Names of enumerated values: the single list used by parsing, messages and to_string
// (the lists: scene_schema.h).

template <class T>
struct Named {
  std::string_view name;
  T value;
};

inline std::string_view name_of(std::string_view s) { return s; }
template <class T>
std::string_view name_of(const Named<T>& n) {
  return n.name;
}

template <class List>
std::string join_names(const List& list) {
  std::string out;
  for (const auto& item : list) {
    if (!out.empty()) out += ", ";
    out += name_of(item);
  }
  return out;
}

// The name of `value` in `names` (a C array or a std::array of Named<T>).
template <class List, class T>
const char* name_for(const List& names, T value) {
  for (const auto& n : names)
    if (n.value == value) return n.name.data();  // the names are NUL-terminated literals
  return "?";
}

// ---------------------------------------------------------------------------
// Formatting for messages.

// "string \"NaN\"", "number 3.5", "array of 2 elements", "object", "null".
std::string describe(const json& v);

// One reference token of a JSON pointer (RFC 6901: '~' -> "~0", '/' -> "~1").
std::string pointer_token(std::string_view key);

// True if `path` is `root` or lies below it.
bool within(const std::string& path, const std::string& root);

// ---------------------------------------------------------------------------
// Number ranges, with their text for messages.

struct Range {
  double lo, hi;
  bool lo_open, hi_open;

  bool contains(double x) const {
    return (lo_open ? x > lo : x >= lo) && (hi_open ? x < hi : x <= hi);
  }
  std::string text() const {
    if (hi == kInf) return (lo_open ? "> " : ">= ") + format_number(lo);
    return std::string("in ") + (lo_open ? "(" : "[") + format_number(lo) + ", " + format_number(hi) + (hi_open ? ")" : "]");
  }
};
constexpr Range closed(double lo, double hi) { return {lo, hi, false, false}; }
constexpr Range open(double lo, double hi) { return {lo, hi, true, true}; }
constexpr Range open_closed(double lo, double hi) { return {lo, hi, true, false}; }
constexpr Range closed_open(double lo, double hi) { return {lo, hi, false, true}; }
constexpr Range at_least(double lo) { return {lo, kInf, false, true}; }
constexpr Range positive() { return {0.0, kInf, true, true}; }

// ---------------------------------------------------------------------------
// Where the scene text came from: the source name, and which pointers the
// overrides set, so that an error in an overridden value names the override.

struct Origin {
  std::string source;
  std::vector<std::pair<std::string, std::string>> overrides;  // (JSON pointer, "key=value")
  SceneFiles files = SceneFiles::required;  // whether the files a scene names must exist

  std::string source_for(const std::string& field) const {
    if (!field.empty())
      for (auto it = overrides.rbegin(); it != overrides.rend(); ++it)  // the last override wins
        if (within(field, it->first) || within(it->first, field)) return override_source(source, it->second);
    return source;
  }
  static std::string override_source(const std::string& source, const std::string& assignment) {
    return source + " (override " + assignment + ")";
  }
};

// ---------------------------------------------------------------------------
// A JSON value (possibly absent) and its JSON pointer. Every accessor that finds
// the value unacceptable throws a SceneError naming that pointer. The get()
// accessors leave their output (the struct default) untouched when the value is absent.

class Reader {
 public:
  Reader(const json* value, std::string path, const Origin& origin)
      : value_(value), path_(std::move(path)), origin_(&origin) {}

  bool present() const { return value_ != nullptr; }
  bool is_object() const { return value_ && value_->is_object(); }
  bool files_required() const { return origin_->files == SceneFiles::required; }

  [[noreturn]] void fail(const std::string& reason) const {
    throw SceneError(origin_->source_for(path_), path_, reason);
  }

  // A member of this object; absent when this is absent or has no such key.
  Reader operator[](std::string_view key) const {
    const json* child = nullptr;
    if (value_ && value_->is_object())
      if (const auto it = value_->find(key); it != value_->end()) child = &*it;
    return {child, path_ + "/" + pointer_token(key), *origin_};
  }

  // Requires an object whose keys are all in `known`.
  void object(std::span<const std::string_view> known) const {
    if (!present()) return;
    if (!value_->is_object()) fail("expected an object, got " + describe(*value_));
    for (const auto& item : value_->items()) {
      bool ok = false;
      for (std::string_view k : known) ok = ok || item.key() == k;
      if (!ok) (*this)[item.key()].fail("unknown field (known: " + join_names(known) + ")");
    }
  }

  // Requires an array; returns its elements. `what` describes the expected array.
  std::vector<Reader> elements(std::string_view what) const {
    if (!value_->is_array()) fail("expected " + std::string(what) + ", got " + describe(*value_));
    std::vector<Reader> out;
    for (std::size_t i = 0; i < value_->size(); ++i)
      out.emplace_back(&(*value_)[i], path_ + "/" + std::to_string(i), *origin_);
    return out;
  }

  // Requires a finite number.
  double number() const {
    if (!value_->is_number()) fail("expected a number, got " + describe(*value_));
    const double x = value_->get<double>();
    if (!std::isfinite(x)) fail("must be a finite number, got " + format_number(x));
    return x;
  }

  void get(double& out, Range range) const {
    if (!present()) return;
    const double x = number();
    if (!range.contains(x)) fail("must be a number " + range.text() + ", got " + format_number(x));
    out = x;
  }

  void get(int& out, int lo, int hi) const {
    if (!present()) return;
    const double x = number();
    if (x != std::floor(x) || x < lo || x > hi)
      fail("must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + format_number(x));
    out = static_cast<int>(x);
  }

  void get(uint64_t& out) const {
    if (!present()) return;
    if (value_->is_number_unsigned()) {
      out = value_->get<uint64_t>();
      return;
    }
    const double x = number();
    if (x != std::floor(x) || x < 0.0 || x >= 18446744073709551616.0)  // 2^64
      fail("must be a non-negative integer, got " + format_number(x));
    out = static_cast<uint64_t>(x);
  }

  void get(bool& out) const {
    if (!present()) return;
    if (!value_->is_boolean()) fail("expected true or false, got " + describe(*value_));
    out = value_->get<bool>();
  }

  // A non-empty string.
  void get(std::string& out) const {
    if (!present()) return;
    if (!value_->is_string()) fail("expected a string, got " + describe(*value_));
    const auto& s = value_->get_ref<const std::string&>();
    if (s.empty()) fail("must be a non-empty string");
    out = s;
  }

  // A 3-vector of finite numbers.
  void get(Vec3& out) const {
    if (!present()) return;
    if (!value_->is_array() || value_->size() != 3) fail("expected an array of 3 numbers, got " + describe(*value_));
    Vec3 v;
    const auto e = elements("an array of 3 numbers");
    for (int i = 0; i < 3; ++i) v[i] = e[i].number();  // in order: the first bad element is reported
    out = v;
  }

  // One of `names` (the entries' names); nullptr when absent. `what` names the kind for messages.
  template <class List>
  auto pick(std::string_view what, const List& names) const -> decltype(std::data(names)) {
    if (!present()) return nullptr;
    if (!value_->is_string()) fail("expected a string, got " + describe(*value_));
    const auto& s = value_->get_ref<const std::string&>();
    for (const auto& n : names)
      if (name_of(n) == s) return &n;
    fail("unknown " + std::string(what) + " '" + s + "' (known: " + join_names(names) + ")");
  }

  template <class T, std::size_t N>
  void get(T& out, std::string_view what, const Named<T> (&names)[N]) const {
    if (const auto* n = pick(what, names)) out = n->value;
  }
  template <class T, std::size_t N>
  void get(T& out, std::string_view what, const std::array<Named<T>, N>& names) const {
    if (const auto* n = pick(what, names)) out = n->value;
  }

 private:
  const json* value_;  // nullptr: absent
  std::string path_;
  const Origin* origin_;
};

// ---------------------------------------------------------------------------
// JSON text and overrides (scene_reader.cpp).

// The JSON value of `text`; invalid JSON is a SceneError naming `source`, the line and the column.
json parse_json(const std::string& text, const std::string& source);

// Sets root at the dotted `key` (creating missing objects); returns the JSON pointer it set.
std::string apply_override(json& root, const std::string& key, const std::string& value, const std::string& source);

}  // namespace palpate::scene_io
