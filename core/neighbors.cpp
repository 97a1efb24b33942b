#include "core/neighbors.h"

#include <nanoflann.hpp>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace palpate {

namespace {

// nanoflann dataset adaptor over the existing 3 x n array (no copy).
struct PointsAdaptor {
  const Points& points;
  size_t kdtree_get_point_count() const { return static_cast<size_t>(points.cols()); }
  double kdtree_get_pt(size_t i, size_t dim) const { return points(static_cast<Eigen::Index>(dim), static_cast<Eigen::Index>(i)); }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const { return false; }
};

using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, PointsAdaptor>,
                                                   PointsAdaptor, 3, size_t>;

std::string fmt_counts(const char* format, int a, int b) {
  char buffer[160];
  std::snprintf(buffer, sizeof buffer, format, a, b);
  return buffer;
}

}  // namespace

Neighborhoods k_nearest_neighbors(const Points& positions, int k) {
  const int n = static_cast<int>(positions.cols());
  if (k < 1 || k >= n)
    throw std::invalid_argument(fmt_counts("k_nearest_neighbors: needs 1 <= k < n, got k = %d, n = %d", k, n));
  PointsAdaptor adaptor{positions};
  KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();

  Neighborhoods nb;
  nb.offset.resize(n + 1);
  nb.index.resize(static_cast<size_t>(n) * k);
  nb.dist2.resize(static_cast<size_t>(n) * k);
  std::vector<size_t> found(k + 1);
  std::vector<double> found_dist2(k + 1);
  for (int i = 0; i < n; ++i) {
    nb.offset[i] = i * k;
    const Vec3 query = positions.col(i);
    const size_t count = tree.knnSearch(query.data(), k + 1, found.data(), found_dist2.data());
    int out = i * k;
    for (size_t a = 0; a < count && out < (i + 1) * k; ++a) {
      if (static_cast<int>(found[a]) == i) continue;  // skip the particle itself
      nb.index[out] = static_cast<int>(found[a]);
      nb.dist2[out] = found_dist2[a];
      ++out;
    }
    if (out != (i + 1) * k) throw std::runtime_error("k_nearest_neighbors: duplicate particle positions");
  }
  nb.offset[n] = n * k;
  return nb;
}

}  // namespace palpate
