#pragma once
// Command-line helpers shared by the palpate tools (clients/, bench/).
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace palpate::cli {

// Walks argv after the program name:
//   for (cli::Arguments args(argc, argv); args.next();)
//     if (args.flag() == "--scene") scene = args.value(); ...
// value() takes the argument after the flag, or throws "FLAG needs a value".
class Arguments {
 public:
  Arguments(int argc, char** argv) : argc_(argc), argv_(argv) {}
  bool next() {
    if (++index_ >= argc_) return false;
    flag_ = argv_[index_];
    return true;
  }
  const std::string& flag() const { return flag_; }
  std::string value() {
    if (index_ + 1 >= argc_) throw std::invalid_argument(flag_ + " needs a value");
    return argv_[++index_];
  }

 private:
  int argc_;
  char** argv_;
  int index_ = 0;
  std::string flag_;
};

// "--set KEY=VALUE": the scene override (KEY a dotted field path, validated with the scene).
inline std::pair<std::string, std::string> scene_override(const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    throw std::invalid_argument("--set expects KEY=VALUE, got '" + assignment + "'");
  return {assignment.substr(0, eq), assignment.substr(eq + 1)};
}

// A comma-separated list of positive numbers ("--forces 10,50.5"); T = double or int.
template <class T = double>
std::vector<T> positive_list(const std::string& text, const std::string& option) {
  std::vector<T> values;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    size_t used = 0;
    double v = NAN;
    try {
      v = std::stod(item, &used);
    } catch (const std::logic_error&) {
      used = 0;
    }
    if (used != item.size() || !std::isfinite(v) || v <= 0 || (std::is_integral_v<T> && v != std::floor(v)))
      throw std::invalid_argument(option + ": '" + item + "' is not a positive " +
                                  (std::is_integral_v<T> ? "integer" : "number"));
    values.push_back(static_cast<T>(v));
  }
  if (values.empty()) throw std::invalid_argument(option + ": empty list");
  return values;
}

}  // namespace palpate::cli
