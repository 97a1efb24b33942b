#include "core/surface.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace palpate {

SurfaceTriangles lattice_surface(const Eigen::Vector3i& n) {
  auto index = [&n](const Eigen::Vector3i& p) { return p[0] + n[0] * (p[1] + n[1] * p[2]); };
  int count = 0;
  for (int k = 0; k < 3; ++k) count += 4 * (n[(k + 1) % 3] - 1) * (n[(k + 2) % 3] - 1);
  SurfaceTriangles tri(3, count);
  int t = 0;
  // Face normal to axis k: cells over the axes u = k+1, v = k+2 (cyclic, so e_u x e_v = e_k).
  for (int k = 0; k < 3; ++k) {
    const int u = (k + 1) % 3, v = (k + 2) % 3;
    for (int side = 0; side < 2; ++side)
      for (int b = 0; b + 1 < n[v]; ++b)
        for (int a = 0; a + 1 < n[u]; ++a) {
          Eigen::Vector3i p = Eigen::Vector3i::Zero();
          p[k] = side == 0 ? 0 : n[k] - 1;
          auto at = [&](int du, int dv) {
            Eigen::Vector3i q = p;
            q[u] = a + du;
            q[v] = b + dv;
            return index(q);
          };
          const int c00 = at(0, 0), c10 = at(1, 0), c11 = at(1, 1), c01 = at(0, 1);
          if (side == 1) {  // outward +e_k: counterclockwise in (u, v)
            tri.col(t++) << c00, c10, c11;
            tri.col(t++) << c00, c11, c01;
          } else {  // outward -e_k: clockwise in (u, v)
            tri.col(t++) << c00, c11, c10;
            tri.col(t++) << c00, c01, c11;
          }
        }
  }
  return tri;
}

SurfaceTriangles cloud_surface(const NodeCloud& cloud) {
  if (!cloud.boundary_triangles.empty()) {
    SurfaceTriangles tri(3, static_cast<Eigen::Index>(cloud.boundary_triangles.size()));
    for (size_t t = 0; t < cloud.boundary_triangles.size(); ++t)
      for (int a = 0; a < 3; ++a) tri(a, static_cast<Eigen::Index>(t)) = cloud.boundary_triangles[t][a];
    return tri;
  }
  if ((cloud.lattice_size.array() >= 2).all()) return lattice_surface(cloud.lattice_size);
  return SurfaceTriangles(3, 0);
}

namespace {

// Highest z with |(cx, cy, z) - p| <= r (a vertex), or -inf.
double vertex_height(const Vec3& p, double cx, double cy, double r) {
  const double d2 = (p[0] - cx) * (p[0] - cx) + (p[1] - cy) * (p[1] - cy);
  return d2 <= r * r ? p[2] + std::sqrt(r * r - d2) : -INFINITY;
}

// Highest z at distance r from the segment p0 p1 with the closest point inside the
// segment (the edge's cylinder), or -inf; the ends are the vertices' business.
double edge_height(const Vec3& p0, const Vec3& p1, double cx, double cy, double r) {
  const Vec3 e = p1 - p0;
  const double ee = e.squaredNorm();
  const double h2 = e[0] * e[0] + e[1] * e[1];
  if (!(h2 > 1e-24 * ee)) return -INFINITY;  // vertical edge: its highest contact is at its top vertex
  // w(z) = c(z) - p0 = w0 + z e_z; |w - (w.e/ee) e|^2 = r^2 is a quadratic A z^2 + 2 B z + C = 0.
  const Vec3 w0(cx - p0[0], cy - p0[1], -p0[2]);
  const Vec3 ez(0, 0, 1);
  const Vec3 q0 = w0 - (w0.dot(e) / ee) * e, q1 = ez - (e[2] / ee) * e;  // perpendicular parts
  const double A = q1.squaredNorm(), B = q0.dot(q1), C = q0.squaredNorm() - r * r;
  const double disc = B * B - A * C;
  if (disc < 0) return -INFINITY;
  const double z = (-B + std::sqrt(disc)) / A;
  const double s = (w0.dot(e) + z * e[2]) / ee;
  return s >= 0 && s <= 1 ? z : -INFINITY;
}

// Highest z where the sphere touches the triangle's interior (its centre at distance r
// from the plane, projecting inside the triangle), or -inf.
double face_height(const Vec3& a, const Vec3& b, const Vec3& c, double cx, double cy, double r) {
  const Vec3 normal = (b - a).cross(c - a);
  if (normal[2] == 0) return -INFINITY;  // a vertical face: edges and vertices bound it
  // The line meets the plane at z0; the centre is r from the plane at z0 + r |n| / |n_z|.
  const double z0 = a[2] - (normal[0] * (cx - a[0]) + normal[1] * (cy - a[1])) / normal[2];
  const double slope = normal[0] == 0 && normal[1] == 0 ? 1.0 : normal.norm() / std::abs(normal[2]);
  const double z = z0 + r * slope;
  // The centre's foot on the plane, in barycentric coordinates.
  const Vec3 unit = normal.normalized();
  const Vec3 centre(cx, cy, z);
  const Vec3 foot = centre - unit.dot(centre - a) * unit;
  const double area2 = normal.squaredNorm();
  const double la = (c - b).cross(foot - b).dot(normal) / area2;
  const double lb = (a - c).cross(foot - c).dot(normal) / area2;
  const double lc = 1.0 - la - lb;
  constexpr double kInside = -1e-12;
  return la >= kInside && lb >= kInside && lc >= kInside ? z : -INFINITY;
}

}  // namespace

double sphere_first_contact_height(const Points& X, const SurfaceTriangles& triangles, double cx, double cy,
                                   double radius) {
  double top = -INFINITY;
  for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
    const Vec3 a = X.col(triangles(0, t)), b = X.col(triangles(1, t)), c = X.col(triangles(2, t));
    // Cheap rejection: the footprint misses the triangle's bounding box.
    if (std::min({a[0], b[0], c[0]}) > cx + radius || std::max({a[0], b[0], c[0]}) < cx - radius ||
        std::min({a[1], b[1], c[1]}) > cy + radius || std::max({a[1], b[1], c[1]}) < cy - radius)
      continue;
    top = std::max({top, face_height(a, b, c, cx, cy, radius), vertex_height(a, cx, cy, radius),
                    vertex_height(b, cx, cy, radius), vertex_height(c, cx, cy, radius),
                    edge_height(a, b, cx, cy, radius), edge_height(b, c, cx, cy, radius),
                    edge_height(c, a, cx, cy, radius)});
  }
  return top;
}

}  // namespace palpate
