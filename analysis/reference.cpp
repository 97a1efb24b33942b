#include "analysis/reference.h"

#include <chrono>
#include <fstream>
#include <cmath>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "core/model.h"
#include "core/node_cloud.h"
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

std::string vec_text(const Vec3& v) {
  std::ostringstream o;
  o.precision(12);
  o << "[" << v[0] << "," << v[1] << "," << v[2] << "]";
  return o.str();
}

}  // namespace

std::string reference_key(const Scene& scene) {
  std::ostringstream o;
  o.precision(12);
  o << "box=" << vec_text(scene.box.min) << vec_text(scene.box.max) << " E=" << scene.material.young_modulus
    << " nu=" << scene.material.poisson_ratio << " fixed=" << scene.fixed_faces << " R=" << scene.indenter.radius
    << " site=";
  if (scene.indenter.position_given)
    o << "[" << scene.indenter.position[0] << "," << scene.indenter.position[1] << "]";
  else
    o << "centre";
  return o.str();
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
    Scene s = scene;
    s.model = "hex_fem";
    s.hex_fem.formulation = HexFormulation::linear;
    s.distribution.type = DistributionType::graded_grid;
    s.distribution.per_edge = per_edge;
    s.distribution.spacing = 0.0;
    s.distribution.focus_given = false;
    s.distribution.first_spacing =
        family_first_spacing(height, options.base_per_edge, base_first_spacing, per_edge);
    s.material.law = MaterialLaw::stvk;       // the hex FEM has its own (linear) law
    s.integrator.allow_unstable_dt = true;    // a static solve: no time step to be stable
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
  const size_t L = ref.levels.size();
  auto h_of = [&](size_t k) { return 1.0 / (ref.levels[k].per_edge - 1); };
  for (size_t f = 0; f < forces.size(); ++f) {
    auto extrapolate = [&](size_t first, double& d_star, double& p) {
      const double h[3] = {h_of(first), h_of(first + 1), h_of(first + 2)};
      const double d[3] = {ref.levels[first].indentation[f], ref.levels[first + 1].indentation[f],
                           ref.levels[first + 2].indentation[f]};
      return richardson(h, d, d_star, p);
    };
    // Richardson only where the three finest levels converge monotonically at a plausible
    // order; contact makes the sequence oscillate (nodes enter the contact ring by ring),
    // and then the finest level stands, with the spread of the three finest as uncertainty.
    double d_star, p;
    const double finest = ref.levels[L - 1].indentation[f];
    bool ok = extrapolate(L - 3, d_star, p) && p >= 0.5 && p <= 4.0;
    double d_coarse = d_star, p_coarse = p;  // the next coarser triple must agree on the order
    if (ok && L >= 4) ok = extrapolate(L - 4, d_coarse, p_coarse) && std::abs(p_coarse - p) <= 0.5 * p;
    double uncertainty;
    if (ok) {
      uncertainty = std::max(1.25 * std::abs(d_star - finest), std::abs(d_star - d_coarse));
    } else {
      d_star = finest;
      p = 0.0;
      double lo = finest, hi = finest;
      for (size_t k = L - 3; k < L; ++k) {
        lo = std::min(lo, ref.levels[k].indentation[f]);
        hi = std::max(hi, ref.levels[k].indentation[f]);
      }
      uncertainty = hi - lo;
    }
    ref.indentation.push_back(d_star);
    ref.uncertainty.push_back(uncertainty);
    ref.order.push_back(p);
  }
  return ref;
}

double reference_indentation(const Reference& ref, double force) {
  const auto& F = ref.forces;
  for (size_t k = 0; k < F.size(); ++k)
    if (std::abs(F[k] - force) <= 1e-9 * std::max(1.0, std::abs(force))) return ref.indentation[k];
  // Piecewise linear in d^(3/2) against F (exact for a Hertzian curve), inside the range.
  for (size_t k = 0; k + 1 < F.size(); ++k) {
    const double lo = std::min(F[k], F[k + 1]), hi = std::max(F[k], F[k + 1]);
    if (force < lo || force > hi) continue;
    const double t = (force - F[k]) / (F[k + 1] - F[k]);
    const double a = std::pow(ref.indentation[k], 1.5), b = std::pow(ref.indentation[k + 1], 1.5);
    return std::pow(a + t * (b - a), 2.0 / 3.0);
  }
  return NAN;
}

Reference load_reference(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw std::runtime_error("cannot read " + file.string());
  std::stringstream text;
  text << in.rdbuf();
  return reference_from_json(text.str());
}

std::optional<Reference> find_reference(const Scene& scene, const std::filesystem::path& folder) {
  std::error_code ec;
  if (!std::filesystem::is_directory(folder, ec)) return std::nullopt;
  const std::string key = reference_key(scene);
  for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
    if (entry.path().extension() != ".json") continue;
    try {
      Reference ref = load_reference(entry.path());
      if (ref.key == key) return ref;
    } catch (const std::runtime_error&) {
      continue;  // not a reference file
    }
  }
  return std::nullopt;
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
  j["levels"] = levels;
  return j.dump(1);
}

Reference reference_from_json(const std::string& text) {
  Reference ref;
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    ref.key = j.at("key").get<std::string>();
    ref.forces = j.at("forces").get<std::vector<double>>();
    ref.indentation = j.at("indentation").get<std::vector<double>>();
    ref.uncertainty = j.at("uncertainty").get<std::vector<double>>();
    ref.order = j.at("order").get<std::vector<double>>();
    for (const auto& l : j.at("levels")) {
      ReferenceLevel level;
      level.per_edge = l.at("per_edge").get<int>();
      level.nodes = l.at("nodes").get<int>();
      level.first_spacing = l.at("first_spacing").get<double>();
      level.indentation = l.at("indentation").get<std::vector<double>>();
      level.seconds = l.at("seconds").get<double>();
      ref.levels.push_back(std::move(level));
    }
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(std::string("not a palpate reference: ") + e.what());
  }
  if (ref.indentation.size() != ref.forces.size() || ref.uncertainty.size() != ref.forces.size())
    throw std::runtime_error("not a palpate reference: the lists differ in length");
  return ref;
}

}  // namespace palpate
