#pragma once
// k-nearest-neighbour support domains (nanoflann k-d tree), in CSR form.
#include <vector>

#include "core/types.h"

namespace palpate {

struct Neighborhoods {
  std::vector<int> offset;    // n+1; neighbours of i are index[offset[i] .. offset[i+1])
  std::vector<int> index;     // the particle itself excluded, nearest first
  std::vector<double> dist2;  // squared reference distances, same layout, m^2
};

// The k nearest other particles of every particle (k < n).
Neighborhoods k_nearest_neighbors(const Points& positions, int k);

}  // namespace palpate
