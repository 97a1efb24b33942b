#include "core/material_field.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace palpate {

LameParameters lame_parameters(double E, double nu) {
  return {E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))};
}

CellMaterial cell_material(const MaterialSpec& material, const Vec3& cell_min, const Vec3& cell_max) {
  const LameParameters matrix = lame_parameters(material.young_modulus, material.poisson_ratio);
  CellMaterial out;
  if (material.inclusions.empty()) {
    out.lambda = matrix.lambda;
    out.mu = matrix.mu;
    out.density = material.density;
    return out;
  }
  // The inclusions' Lame parameters (few; recomputed per cell, the build is not hot).
  std::vector<LameParameters> lame;
  for (const InclusionSpec& inc : material.inclusions) lame.push_back(lame_parameters(inc.young_modulus, inc.poisson_ratio));
  constexpr int S = kMaterialSamplesPerAxis;
  const int count = static_cast<int>(material.inclusions.size());
  // Counts of samples per material (index count = the matrix), so that a cell wholly in
  // one material gets its parameters exactly (no sum of S^3 equal fractions).
  std::vector<int> samples(count + 1, 0);
  const Vec3 size = cell_max - cell_min;
  for (int c = 0; c < S; ++c)
    for (int b = 0; b < S; ++b)
      for (int a = 0; a < S; ++a) {
        const Vec3 p = cell_min + Vec3((a + 0.5) / S * size[0], (b + 0.5) / S * size[1], (c + 0.5) / S * size[2]);
        int which = count;
        for (int k = count - 1; k >= 0; --k)  // the last inclusion containing p wins
          if (material.inclusions[k].contains(p)) {
            which = k;
            break;
          }
        ++samples[which];
      }
  constexpr int total = S * S * S;
  // (1.16); exact (the value itself) when every material sampled has the same value,
  // so a cell wholly in one material, or an inclusion equal to the matrix, changes nothing.
  auto blend = [&](double matrix_value, auto&& inclusion_value) {
    auto value_of = [&](int k) { return k == count ? matrix_value : static_cast<double>(inclusion_value(k)); };
    bool same = true;
    double first = 0.0, sum = 0.0;
    bool seen = false;
    for (int k = 0; k <= count; ++k) {
      if (samples[k] == 0) continue;
      const double v = value_of(k);
      if (!seen) first = v, seen = true;
      same = same && v == first;
      sum += samples[k] * v;
    }
    return same ? first : sum / total;
  };
  out.lambda = blend(matrix.lambda, [&](int k) { return lame[k].lambda; });
  out.mu = blend(matrix.mu, [&](int k) { return lame[k].mu; });
  out.density = blend(material.density, [&](int k) { return material.inclusions[k].density; });
  out.inclusion_fraction = static_cast<double>(total - samples[count]) / total;
  return out;
}

MaterialField material_field(const MaterialSpec& material, const Points& cell_min, const Points& cell_max) {
  const int n = static_cast<int>(cell_min.cols());
  MaterialField f;
  f.lambda.resize(n);
  f.mu.resize(n);
  f.density.resize(n);
  f.inclusion_fraction.resize(n);
  for (int i = 0; i < n; ++i) {
    const CellMaterial c = cell_material(material, cell_min.col(i), cell_max.col(i));
    f.lambda[i] = c.lambda;
    f.mu[i] = c.mu;
    f.density[i] = c.density;
    f.inclusion_fraction[i] = c.inclusion_fraction;
  }
  return f;
}

int64_t group_inclusion_tag(const MaterialSpec& material, size_t k, const NodeCloud& cloud, const std::string& source) {
  const InclusionSpec& inc = material.inclusions[k];
  const std::string where = "/material/inclusions/" + std::to_string(k) + "/group";
  if (cloud.tetrahedra.empty())
    throw SceneError(source, where,
                     "a group names a physical volume of a tetrahedral mesh; this body is not a mesh (use a sphere "
                     "or a box)");
  std::string names;
  for (const NodeCloud::VolumeGroup& g : cloud.volume_groups) {
    if (g.name == inc.group) return g.tag;
    names += (names.empty() ? "'" : ", '") + g.name + "'";
  }
  throw SceneError(source, where,
                   "the mesh has no physical volume group named '" + inc.group + "' (it has: " +
                       (names.empty() ? std::string("none") : names) + ")");
}

void blend_group_inclusions(const MaterialSpec& material, const NodeCloud& cloud, const std::string& source,
                            MaterialField& field) {
  for (size_t k = 0; k < material.inclusions.size(); ++k) {
    const InclusionSpec& inc = material.inclusions[k];
    if (inc.shape != InclusionShape::group) continue;
    const int64_t tag = group_inclusion_tag(material, k, cloud, source);
    // f_i from the lumped tetrahedra (the quarter of each V_t its four vertices share).
    const int n = static_cast<int>(cloud.positions.cols());
    std::vector<double> in_group(n, 0.0), total(n, 0.0);
    for (size_t t = 0; t < cloud.tetrahedra.size(); ++t) {
      const auto& v = cloud.tetrahedra[t];
      const Vec3 a = cloud.positions.col(v[0]);
      const double quarter =
          std::abs((cloud.positions.col(v[1]) - a).dot((cloud.positions.col(v[2]) - a).cross(cloud.positions.col(v[3]) - a))) /
          24.0;
      for (int c = 0; c < 4; ++c) {
        total[v[c]] += quarter;
        if (cloud.tetrahedron_region[t] == tag) in_group[v[c]] += quarter;
      }
    }
    const LameParameters lame = lame_parameters(inc.young_modulus, inc.poisson_ratio);
    for (int i = 0; i < n; ++i) {
      if (in_group[i] == 0.0) continue;
      if (in_group[i] == total[i]) {  // wholly inside: exactly the group's (1.16)
        field.lambda[i] = lame.lambda, field.mu[i] = lame.mu, field.density[i] = inc.density;
        field.inclusion_fraction[i] = 1.0;
        continue;
      }
      const double f = in_group[i] / total[i];
      field.lambda[i] = (1 - f) * field.lambda[i] + f * lame.lambda;
      field.mu[i] = (1 - f) * field.mu[i] + f * lame.mu;
      field.density[i] = (1 - f) * field.density[i] + f * inc.density;
      field.inclusion_fraction[i] = std::max(field.inclusion_fraction[i], f);
    }
  }
}

void lattice_cells(const Points& X, const Eigen::Vector3i& per_axis, Points& cell_min, Points& cell_max) {
  const int nx = per_axis[0], ny = per_axis[1], nz = per_axis[2];
  const int n = static_cast<int>(X.cols());
  cell_min.resize(3, n);
  cell_max.resize(3, n);
  auto node = [&](int a, int b, int c) { return a + nx * (b + ny * c); };
  for (int c = 0; c < nz; ++c)
    for (int b = 0; b < ny; ++b)
      for (int a = 0; a < nx; ++a) {
        const int i = node(a, b, c);
        const int index[3] = {a, b, c}, count[3] = {nx, ny, nz};
        for (int axis = 0; axis < 3; ++axis) {
          int step[3] = {0, 0, 0};
          step[axis] = 1;
          const int k = index[axis];
          const double x = X(axis, i);
          const double prev = k > 0 ? X(axis, node(a - step[0], b - step[1], c - step[2])) : x;
          const double next = k + 1 < count[axis] ? X(axis, node(a + step[0], b + step[1], c + step[2])) : x;
          cell_min(axis, i) = 0.5 * (prev + x);
          cell_max(axis, i) = 0.5 * (x + next);
        }
      }
}

void cube_cells(const Points& X, const std::vector<double>& volume, Points& cell_min, Points& cell_max) {
  const int n = static_cast<int>(X.cols());
  cell_min.resize(3, n);
  cell_max.resize(3, n);
  for (int i = 0; i < n; ++i) {
    const double half = 0.5 * std::cbrt(volume[i]);
    cell_min.col(i) = X.col(i).array() - half;
    cell_max.col(i) = X.col(i).array() + half;
  }
}

}  // namespace palpate
