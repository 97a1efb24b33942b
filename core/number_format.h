#pragma once
// Numbers in the core's messages (the scene reader's, the mesh readers'): one format.
#include <string>

namespace palpate {

// The shortest text that reads back as x (std::to_chars), with a compact exponent: 0.7,
// 1000, 1e12, 1e-6, 2.8284271247461903. A message quotes the value the program holds, not
// a rounding of it: a value just outside a range never prints as the range's bound, and
// two numbers that differ never print alike.
std::string format_number(double x);

}  // namespace palpate
