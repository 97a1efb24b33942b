#include "core/number_format.h"

#include <charconv>
#include <cstddef>

namespace palpate {

std::string format_number(double x) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, x);
  std::string s(buf, res.ptr);
  if (const auto e = s.find('e'); e != std::string::npos) {
    std::size_t digits = e + 1;
    const bool negative = s[digits] == '-';
    if (s[digits] == '+' || s[digits] == '-') ++digits;
    while (digits + 1 < s.size() && s[digits] == '0') ++digits;
    s = s.substr(0, e + 1) + (negative ? "-" : "") + s.substr(digits);
  }
  return s;
}

}  // namespace palpate
