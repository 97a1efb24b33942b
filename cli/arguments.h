#pragma once
// Command-line helpers shared by the palpate programs (tools/, clients/, bench/, server/).
//
// The convention: every program has a usage text (what it does, every option with
// its default, the exit statuses); --help or -h prints it to stdout and exits 0; a
// wrong argument prints "PROGRAM: REASON", a blank line and the usage to stderr and
// exits 2. Values are parsed whole and refused with the option's name:
// "--rate: 'abc' is not a number".
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace palpate::cli {

// The whole text as a finite number, else std::invalid_argument "OPTION: 'TEXT' is not a number".
inline double number(const std::string& text, const std::string& option) {
  size_t used = 0;
  double v = NAN;
  try {
    v = std::stod(text, &used);
  } catch (const std::logic_error&) {
    used = 0;
  }
  if (text.empty() || used != text.size() || !std::isfinite(v))
    throw std::invalid_argument(option + ": '" + text + "' is not a number");
  return v;
}

// The whole text as an integer, else std::invalid_argument "OPTION: 'TEXT' is not an integer".
inline long long integer(const std::string& text, const std::string& option) {
  size_t used = 0;
  long long v = 0;
  try {
    v = std::stoll(text, &used);
  } catch (const std::logic_error&) {
    used = 0;
  }
  if (text.empty() || used != text.size()) throw std::invalid_argument(option + ": '" + text + "' is not an integer");
  return v;
}

// Walks argv after the program name:
//   for (cli::Arguments args(argc, argv); args.next();)
//     if (args.flag() == "--scene") scene = args.value(); ...
// value() takes the argument after the flag, or throws "FLAG needs a value";
// number() and integer() parse it whole (cli::number, cli::integer).
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
  double number() { return cli::number(value(), flag_); }
  long long integer() { return cli::integer(value(), flag_); }
  // number() or integer() within [lo, hi], else "FLAG: must be in [lo, hi], got TEXT".
  double number(double lo, double hi) { return within(number(), lo, hi); }
  long long integer(long long lo, long long hi) { return within(integer(), lo, hi); }
  bool help() const { return flag_ == "--help" || flag_ == "-h"; }

 private:
  template <class T>
  T within(T v, T lo, T hi) const {
    if (!(v >= lo && v <= hi)) {
      std::ostringstream s;
      s << flag_ << ": must be in [" << lo << ", " << hi << "], got " << argv_[index_];
      throw std::invalid_argument(s.str());
    }
    return v;
  }

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

// A wrong argument: "PROGRAM: REASON", a blank line and the usage on stderr; exit 2.
[[noreturn]] inline void usage_error(const char* program, const std::string& reason, const char* usage) {
  std::fprintf(stderr, "%s: %s\n\n%s", program, reason.c_str(), usage);
  std::exit(2);
}

// Walks argv with the convention: --help / -h prints `usage` to stdout and exits 0;
// handle(args) is called for every other flag and returns false for one it does not
// know; what it throws (a missing or malformed value) and an unknown option go to
// usage_error.
template <class Handle>
void parse_or_exit(int argc, char** argv, const char* program, const char* usage, Handle&& handle) {
  try {
    for (Arguments args(argc, argv); args.next();) {
      if (args.help()) {
        std::fputs(usage, stdout);
        std::exit(0);
      }
      if (!handle(args)) throw std::invalid_argument("unknown option '" + args.flag() + "'");
    }
  } catch (const std::exception& e) {
    usage_error(program, e.what(), usage);
  }
}

// A comma-separated list of finite numbers ("--forces 0,10.5,-3").
inline std::vector<double> number_list(const std::string& text, const std::string& option) {
  std::vector<double> values;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) values.push_back(number(item, option));
  if (values.empty()) throw std::invalid_argument(option + ": empty list");
  return values;
}

// A comma-separated list of positive numbers ("--forces 10,50.5"); T = double or an
// integer type: each item is a number_list item that must also be > 0 (and whole).
template <class T = double>
std::vector<T> positive_list(const std::string& text, const std::string& option) {
  std::vector<T> values;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) {
    double v = NAN;
    try {
      v = number(item, option);
    } catch (const std::invalid_argument&) {
    }
    if (!(v > 0) || (std::is_integral_v<T> && v != std::floor(v)))
      throw std::invalid_argument(option + ": '" + item + "' is not a positive " +
                                  (std::is_integral_v<T> ? "integer" : "number"));
    values.push_back(static_cast<T>(v));
  }
  if (values.empty()) throw std::invalid_argument(option + ": empty list");
  return values;
}

}  // namespace palpate::cli
