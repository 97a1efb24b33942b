#include "analysis/reference.h"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <cmath>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "core/hex_fem.h"
#include "core/model.h"
#include "core/node_cloud.h"
#include "core/surface.h"
#include "analysis/held_tool_static.h"
#include "analysis/static_contact.h"

namespace palpate {

namespace {

// First spacing of level `per_edge` that keeps the vertical axis's geometric map
// of the base level: r^n = r0^n0 (a one-sided grading over the height L).
double family_first_spacing(double L, int base_per_edge, double base_first_spacing, int per_edge) {
  const int n0 = base_per_edge - 1, n = per_edge - 1;
  const double beta = n0 * std::log(geometric_ratio(base_first_spacing, L, n0));  // n0 log r0
  const double r = std::exp(beta / n);
  return std::abs(r - 1.0) < 1e-12 ? L / n : L * (r - 1.0) / (std::pow(r, n) - 1.0);
}


std::string number_text(double v) {
  std::ostringstream o;
  o.precision(12);
  o << v;
  return o.str();
}


}  // namespace


void check_site(const Scene& scene, const std::string& field) {
  // A mesh body without a box has no top face to check against: any (x, y) over the body is
  // a site (build_model refuses a tool that is not above it).
  if (!scene.box_given) return;
  const Eigen::Vector2d site = indenter_site(scene);
  const double R = scene.indenter.radius;
  const Vec3& lo = scene.box.min;
  const Vec3& hi = scene.box.max;
  const std::string where = std::string("(").append(number_text(site[0])) + ", " + number_text(site[1]) + ") m";
  if (!site.allFinite() || site[0] < lo[0] || site[0] > hi[0] || site[1] < lo[1] || site[1] > hi[1])
    throw std::invalid_argument(field + ": the site " + where + " is off the top face [" + number_text(lo[0]) + ", " +
                                number_text(hi[0]) + "] x [" + number_text(lo[1]) + ", " + number_text(hi[1]) + "] m");
  // Distance to the nearest side wall: the sphere's footprint (radius R) must lie on the face (4.2).
  // The centre itself is always accepted: it is the Hertz experiment's own site, and a sphere
  // wider than the face (the R = 5 m strain study of docs/verification.md) presses it.
  const double wall = std::min({site[0] - lo[0], hi[0] - site[0], site[1] - lo[1], hi[1] - site[1]});
  if (wall < R * (1.0 - 1e-12) && !at_top_face_centre(scene, site))
    throw std::invalid_argument(field + ": the site " + where + " is " + number_text(wall) +
                                " m from a side wall, closer than the indenter radius R = " + number_text(R) +
                                " m: choose a site at least R from every side of the top face");
}

void place_indenter_at_site(Scene& scene, double x, double y, const std::string& field) {
  scene.indenter.position_given = true;
  scene.indenter.position = Vec3(x, y, scene.box.max[2] + scene.indenter.radius);
  check_site(scene, field);
  // Just touching: the height at which the sphere over (x, y) first meets a particle of the
  // undeformed cloud. The cloud is built with the site (a graded lattice graded toward it), and
  // a cloud that follows the tool is refined toward the point of the surface nearest the
  // tool's centre, which depends on the height: so the height is the fixed point of "refine
  // toward the tool, then touch". A body without a box starts with the tool over its top.
  if (!scene.box_given) {
    const Points X = make_node_cloud(scene).positions;
    scene.indenter.position[2] = X.row(2).maxCoeff() + scene.indenter.radius;
  }
  for (int pass = 0; pass < 8; ++pass) {
    const double first_contact = first_contact_height(make_node_cloud(scene).positions, scene.indenter.radius, x, y);
    if (!std::isfinite(first_contact))
      throw std::invalid_argument(field + ": no particle of the body lies under the indenter at the site");
    if (first_contact == scene.indenter.position[2]) break;
    scene.indenter.position[2] = first_contact;
  }
}

double first_contact_height(const Points& X, double R, double x, double y) {
  double first_contact = -INFINITY;
  for (Eigen::Index i = 0; i < X.cols(); ++i) {
    const double r2 = (X(0, i) - x) * (X(0, i) - x) + (X(1, i) - y) * (X(1, i) - y);
    if (r2 < R * R) first_contact = std::max(first_contact, X(2, i) + std::sqrt(R * R - r2));
  }
  return first_contact;
}

double touch_height_at(const Model& model, double x, double y) {
  const Points& X = model.rest_position;
  const double R = model.indenter_radius;
  // With a surface: the sphere's first contact with its triangles (2.16), as build_model
  // measures model.touch_height; on a sloping face (the dome's flank) the particle formula
  // below would put the sphere's bottom, not its side, on the highest particle.
  const double surface_contact = sphere_first_contact_height(X, model.surface_triangles, x, y, R);
  if (std::isfinite(surface_contact)) return surface_contact;
  double surface = -INFINITY;
  for (Eigen::Index i = 0; i < X.cols(); ++i) {
    const double r2 = (X(0, i) - x) * (X(0, i) - x) + (X(1, i) - y) * (X(1, i) - y);
    if (r2 < R * R) surface = std::max(surface, X(2, i));
  }
  return surface + R;  // (4.1); -inf when nothing lies under the sphere
}

double indentation_at_tool(const Model& model, const State& state) {
  const Vec3& c = state.indenter_center;
  return touch_height_at(model, c[0], c[1]) - c[2];  // (4.1), (2.5) at the tool's (x, y)
}


bool richardson(const double h[3], const double d[3], double& extrapolated, double& order) {
  extrapolated = d[2];
  order = 0.0;
  const double ratio = (d[0] - d[1]) / (d[1] - d[2]);
  if (!(ratio > 0.0) || !std::isfinite(ratio)) return false;
  // (h1^p - h2^p) / (h2^p - h3^p) = ratio, increasing in p for h1 > h2 > h3: bisection.
  auto g = [&](double p) {
    return (std::pow(h[0], p) - std::pow(h[1], p)) / (std::pow(h[1], p) - std::pow(h[2], p)) - ratio;
  };
  double lo = 0.05, hi = 12.0;
  if (g(lo) > 0.0 || g(hi) < 0.0) return false;
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    (g(mid) < 0.0 ? lo : hi) = mid;
  }
  order = 0.5 * (lo + hi);
  const double C = (d[1] - d[2]) / (std::pow(h[1], order) - std::pow(h[2], order));
  extrapolated = d[2] - C * std::pow(h[2], order);
  return true;
}

namespace {

// Per quantity k (a force's depth, or a depth's force), Richardson over the levels (h = 1 /
// (per_edge - 1), or first_spacing for a family without per_edge): only where the three
// finest levels converge monotonically at a plausible order and the next coarser triple agrees on it; contact makes the sequence oscillate
// (nodes enter the contact ring by ring), and then the finest level stands, with the spread
// of the three finest as uncertainty.
void extrapolate_levels(const std::vector<ReferenceLevel>& levels, const std::vector<std::vector<double>>& value,
                        std::vector<double>& extrapolated, std::vector<double>& uncertainty,
                        std::vector<double>& order) {
  const size_t L = levels.size();
  auto h_of = [&](size_t k) { return levels[k].per_edge > 1 ? 1.0 / (levels[k].per_edge - 1) : levels[k].first_spacing; };
  for (size_t f = 0; f < value[0].size(); ++f) {
    auto extrapolate = [&](size_t first, double& v_star, double& p) {
      const double h[3] = {h_of(first), h_of(first + 1), h_of(first + 2)};
      const double v[3] = {value[first][f], value[first + 1][f], value[first + 2][f]};
      return richardson(h, v, v_star, p);
    };
    double v_star, p;
    const double finest = value[L - 1][f];
    bool ok = extrapolate(L - 3, v_star, p) && p >= 0.5 && p <= 4.0;
    double v_coarse = v_star, p_coarse = p;
    if (ok && L >= 4) ok = extrapolate(L - 4, v_coarse, p_coarse) && std::abs(p_coarse - p) <= 0.5 * p;
    double u;
    if (ok) {
      u = std::max(1.25 * std::abs(v_star - finest), std::abs(v_star - v_coarse));
    } else {
      v_star = finest;
      p = 0.0;
      double lo = finest, hi = finest;
      for (size_t k = L - 3; k < L; ++k) {
        lo = std::min(lo, value[k][f]);
        hi = std::max(hi, value[k][f]);
      }
      u = hi - lo;
    }
    extrapolated.push_back(v_star);
    uncertainty.push_back(u);
    order.push_back(p);
  }
}

}  // namespace

void extrapolate_indentation(Reference& ref) {
  std::vector<std::vector<double>> per_level;
  for (const ReferenceLevel& level : ref.levels) per_level.push_back(level.indentation);
  extrapolate_levels(ref.levels, per_level, ref.indentation, ref.uncertainty, ref.order);
}

namespace {

// The scene of one reference level: the scene's block as hex bricks of `formulation` on the
// graded lattice of per_edge nodes whose first spacing is `first_spacing`, for a static solve.
Scene level_scene(const Scene& scene, int per_edge, HexFormulation formulation, double first_spacing) {
  Scene s = scene;
  s.model = SolidKind::hex_fem;
  s.hex_fem.formulation = formulation;
  s.distribution.type = DistributionType::graded_grid;
  s.distribution.per_edge = per_edge;
  s.distribution.spacing = 0.0;
  s.distribution.focus_given = false;
  s.distribution.first_spacing = first_spacing;
  // The site: the lattice is graded toward it (focus_given false: graded_focus takes the
  // indenter's (x, y)), so a node lies on it at every level, and the sphere starts just
  // touching that node; only (x, y) of the scene's position is the site.
  if (s.indenter.position_given) s.indenter.position[2] = s.box.max[2] + s.indenter.radius;
  s.material.law = MaterialLaw::stvk;       // the hex FEM has its own laws
  s.integrator.allow_unstable_dt = true;    // a static solve: no time step to be stable
  return s;
}

// A level of the quarter-block family (LargeStrainLattice): the neo-Hookean bricks of the
// quarter of the scene's block on the site's side x >= x_s, y >= y_s, on the lattice of three
// core_graded_axis of per_edge nodes; the cut planes are free here (the mirror conditions are
// the solver's, HeldToolOptions::mirror_axes).
Model quarter_level_model(const Scene& scene, int per_edge, const LargeStrainLattice& lattice, double& spacing) {
  const Eigen::Vector2d site = indenter_site(scene);
  const double symmetry_tolerance = 1e-9 * scene.box.max.norm();  // the site and inclusions on the mirror planes
  const uint32_t faces = scene.fixed_faces;
  if (((faces & face_x_min) != 0) != ((faces & face_x_max) != 0) ||
      ((faces & face_y_min) != 0) != ((faces & face_y_max) != 0))
    throw std::invalid_argument("the quarter-block reference needs fixed faces symmetric about the site");
  if (!scene.fixed_regions.empty())
    throw std::invalid_argument("the quarter-block reference needs a body without fixed regions");
  // Inclusions are blended into the bricks as in the linear reference (1.16); the quarter and
  // its mirror planes hold only if each is symmetric about both planes through the site.
  for (size_t k = 0; k < scene.material.inclusions.size(); ++k) {
    const InclusionSpec& inc = scene.material.inclusions[k];
    const std::string where = "material.inclusions[" + std::to_string(k) + "]: ";
    if (inc.shape == InclusionShape::group)
      throw std::invalid_argument(where + "the quarter-block reference takes sphere and box inclusions only");
    for (int axis = 0; axis < 2; ++axis) {
      const double middle = inc.shape == InclusionShape::sphere ? inc.center[axis] : 0.5 * (inc.min[axis] + inc.max[axis]);
      if (std::abs(middle - site[axis]) > symmetry_tolerance)
        throw std::invalid_argument(where + "the quarter-block reference needs inclusions centred on the tool's axis "
                                            "(symmetric about both mirror planes through the site)");
    }
  }
  if (!scene.box_given || std::abs(site[0] - 0.5 * (scene.box.min[0] + scene.box.max[0])) > symmetry_tolerance ||
      std::abs(site[1] - 0.5 * (scene.box.min[1] + scene.box.max[1])) > symmetry_tolerance)
    throw std::invalid_argument("the quarter-block reference is computed at the centre of the top face of a box");
  const int intervals = per_edge - 1;
  const int core = static_cast<int>(std::lround(lattice.core_share * intervals));
  const double w = lattice.core_half_width;
  spacing = w / core;
  std::vector<double> coord[3] = {core_graded_axis(site[0], scene.box.max[0], intervals, core, w),
                                  core_graded_axis(site[1], scene.box.max[1], intervals, core, w),
                                  core_graded_axis(scene.box.max[2], scene.box.min[2], intervals, core, w)};
  std::reverse(coord[2].begin(), coord[2].end());  // z ascending, the top face last
  Scene s = level_scene(scene, per_edge, HexFormulation::neo_hookean, 0.0);
  s.hex_fem.volumetric_integration = HexVolumetricIntegration::full;  // the bricks (5.4) integrate fully
  s.box.min = Vec3(site[0], site[1], scene.box.min[2]);
  s.fixed_faces = faces & ~(face_x_min | face_y_min);  // the cut planes: the solver's mirrors
  // A plain lattice of the same size is built, then its nodes are moved onto the core-graded
  // axes and the bricks rebuilt: the node order, the fixed faces (the axes' ends are exact) and
  // the indenter's start on the site's node (the top face is flat) are the same.
  s.distribution.type = DistributionType::grid;
  s.distribution.first_spacing = 0.0;
  s.indenter.position_given = true;
  s.indenter.position = Vec3(site[0], site[1], scene.box.max[2] + scene.indenter.radius);
  Model m = build_model(s);
  int i = 0;
  for (int c = 0; c < per_edge; ++c)
    for (int b = 0; b < per_edge; ++b)
      for (int a = 0; a < per_edge; ++a, ++i) m.rest_position.col(i) = Vec3(coord[0][a], coord[1][b], coord[2][c]);
  m.hex = hex_mesh(m.rest_position, Eigen::Vector3i::Constant(per_edge), m.lame_lambda, m.lame_mu,
                   HexFormulation::neo_hookean, HexVolumetricIntegration::full,
                   scene.material.inclusions.empty() ? nullptr : &scene.material);
  return m;
}

}  // namespace

std::vector<double> core_graded_axis(double focus, double end, int intervals, int core_intervals, double core_length) {
  const double length = std::abs(end - focus), sign = end >= focus ? 1.0 : -1.0;
  if (!(core_intervals >= 1 && core_intervals < intervals))
    throw std::invalid_argument("core-graded axis: the core needs at least one interval and one outside it (" +
                                std::to_string(core_intervals) + " of " + std::to_string(intervals) + ")");
  if (!(core_length > 0 && core_length < length))
    throw std::invalid_argument("core-graded axis: the core of " + std::to_string(core_length) +
                                " m does not fit a side of " + std::to_string(length) + " m");
  const double h = core_length / core_intervals;
  const int outer = intervals - core_intervals;
  const double rest = length - core_length;
  if (rest < outer * h * (1 - 1e-12))
    throw std::invalid_argument("core-graded axis: " + std::to_string(outer) + " outer intervals of at least " +
                                std::to_string(h) + " m do not fit the " + std::to_string(rest) +
                                " m outside the core (the outer intervals would shrink)");
  const double r = geometric_ratio(h, rest, outer);
  std::vector<double> coord(intervals + 1);
  coord[0] = focus;
  for (int k = 1; k <= core_intervals; ++k) coord[k] = focus + sign * h * k;
  double step = h, x = coord[core_intervals];
  for (int k = core_intervals + 1; k <= intervals; ++k, step *= r) coord[k] = x += sign * step;
  coord[intervals] = end;  // exact end
  return coord;
}

Reference finite_cube_reference(const Scene& scene, const std::vector<double>& forces, const ReferenceOptions& options,
                                const std::function<void(const std::string&)>& progress) {
  if (options.levels.size() < 3) throw std::invalid_argument("the reference needs at least three levels");
  Reference ref;
  ref.forces = forces;
  ref.key = reference_key(scene);
  const double height = scene.box.max[2] - scene.box.min[2];
  const double base_first_spacing =
      options.base_first_spacing > 0 ? options.base_first_spacing : 0.05 * scene.indenter.radius;
  for (int per_edge : options.levels) {
    const auto start = std::chrono::steady_clock::now();
    const Scene s = level_scene(scene, per_edge, HexFormulation::linear,
                                family_first_spacing(height, options.base_per_edge, base_first_spacing, per_edge));
    const Model model = build_model(s);
    LinearStaticContact solver(model);
    ReferenceLevel level;
    level.per_edge = per_edge;
    level.nodes = model.particle_count;
    level.first_spacing = s.distribution.first_spacing;
    for (double F : forces) {
      const StaticSolution sol = solver.solve(F);
      if (!sol.converged)
        throw std::runtime_error("reference level " + std::to_string(per_edge) + ", F = " + std::to_string(F) +
                                 " N: " + sol.message);
      level.indentation.push_back(sol.indentation);
    }
    level.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (progress) {
      std::ostringstream o;
      o << "reference level " << per_edge << "^3 (" << level.nodes << " nodes, first spacing "
        << level.first_spacing << " m, " << solver.columns_computed() << " compliance columns): " << level.seconds
        << " s";
      progress(o.str());
    }
    ref.levels.push_back(std::move(level));
  }
  extrapolate_indentation(ref);
  return ref;
}

Reference large_strain_reference(const Scene& scene, const std::vector<double>& depths, const std::vector<int>& levels,
                                 const std::function<void(const std::string&)>& progress,
                                 const LargeStrainLattice& lattice) {
  if (levels.size() < 3) throw std::invalid_argument("the reference needs at least three levels");
  if (!at_top_face_centre(scene, indenter_site(scene)))
    throw std::invalid_argument("the large-strain reference is computed at the centre of the top face");
  for (size_t k = 0; k < depths.size(); ++k)
    if (!(depths[k] > 0) || (k > 0 && !(depths[k] > depths[k - 1])))
      throw std::invalid_argument("the depths of the large-strain reference must be positive and increasing");
  Reference ref;
  ref.indentation = depths;
  ref.key = large_strain_reference_key(scene);
  for (int per_edge : levels) {
    const auto start = std::chrono::steady_clock::now();
    const bool quarter = lattice.core_half_width > 0;
    double first_spacing = 0;
    Model model;
    if (quarter) {
      model = quarter_level_model(scene, per_edge, lattice, first_spacing);
    } else {
      // The family of graded lattices of finite_cube_reference (a node at the site, one
      // geometric map refined uniformly), so Richardson applies in the same way.
      Scene s = level_scene(scene, per_edge, HexFormulation::neo_hookean,
                            family_first_spacing(scene.box.max[2] - scene.box.min[2], ReferenceOptions{}.base_per_edge,
                                                 0.05 * scene.indenter.radius, per_edge));
      s.hex_fem.volumetric_integration = HexVolumetricIntegration::full;  // the bricks (5.4) integrate fully
      model = build_model(s);
      first_spacing = s.distribution.first_spacing;
    }
    HeldToolOptions held;
    if (quarter) held.mirror_axes = {0, 1};
    const double multiplicity = quarter ? 4.0 : 1.0;  // the whole block's force from the quarter's
    HeldToolStatics statics(model, held);
    ReferenceLevel level;
    level.per_edge = per_edge;
    level.nodes = model.particle_count;
    level.first_spacing = first_spacing;
    int iterations = 0;
    std::vector<double> contact_radius;
    for (double d : depths) {
      const HeldToolSolution sol = statics.solve(model.indenter_start - Vec3(0, 0, d));
      if (!sol.converged)
        throw std::runtime_error("large-strain reference level " + std::to_string(per_edge) + ", d = " +
                                 std::to_string(d) + " m: " + sol.message);
      level.forces.push_back(multiplicity * sol.tool_force[2]);
      level.indentation.push_back(d);
      iterations += sol.newton_iterations;
      // The contact radius: the farthest pressed node from the tool's axis (deformed).
      double radius = 0;
      for (int i = 0; i < model.particle_count; ++i)
        if (statics.contact_pressure()[i] > 0)
          radius = std::max(radius, (statics.positions().col(i).head<2>() - model.indenter_start.head<2>()).norm());
      contact_radius.push_back(radius);
    }
    level.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (progress) {
      std::ostringstream o;
      o << "large-strain reference level " << per_edge << "^3 (" << (quarter ? "quarter, " : "") << level.nodes
        << " nodes, spacing at the site " << first_spacing << " m, " << iterations
        << " Newton iterations in all): " << level.seconds << " s; F (N) at the depths:";
      for (double F : level.forces) o << " " << F;
      o << "; contact radius (m):";
      for (double a : contact_radius) o << " " << a;
      progress(o.str());
    }
    ref.levels.push_back(std::move(level));
  }
  std::vector<std::vector<double>> per_level;
  for (const ReferenceLevel& level : ref.levels) per_level.push_back(level.forces);
  std::vector<double> force_uncertainty;
  extrapolate_levels(ref.levels, per_level, ref.forces, force_uncertainty, ref.order);
  // The uncertainty in depth at a given force: the force's, divided by the slope dF/dd of
  // the extrapolated curve (one-sided at the ends).
  for (size_t k = 0; k < depths.size(); ++k) {
    const size_t a = k == 0 ? 0 : k - 1, b = std::min(k + 1, depths.size() - 1);
    const double slope = b > a ? (ref.forces[b] - ref.forces[a]) / (depths[b] - depths[a])
                               : 1.5 * ref.forces[k] / depths[k];  // one depth: Hertz's F ~ d^(3/2)
    ref.uncertainty.push_back(force_uncertainty[k] / slope);
  }
  return ref;
}





std::string reference_to_json(const Reference& ref) {
  nlohmann::json j;
  j["key"] = ref.key;
  j["forces"] = ref.forces;
  j["indentation"] = ref.indentation;
  j["uncertainty"] = ref.uncertainty;
  j["order"] = ref.order;
  nlohmann::json levels = nlohmann::json::array();
  for (const auto& l : ref.levels)
    levels.push_back({{"per_edge", l.per_edge},
                      {"nodes", l.nodes},
                      {"first_spacing", l.first_spacing},
                      {"indentation", l.indentation},
                      {"seconds", l.seconds}});
  for (size_t k = 0; k < ref.levels.size(); ++k)
    if (!ref.levels[k].forces.empty()) levels[k]["forces"] = ref.levels[k].forces;
  j["levels"] = levels;
  return j.dump(1);
}


}  // namespace palpate
