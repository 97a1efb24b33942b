#include "core/reference_file.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "core/mesh_reader.h"

namespace palpate {

namespace {

std::string vec_text(const Vec3& v) {
  std::ostringstream o;
  o.precision(12);
  o << "[" << v[0] << "," << v[1] << "," << v[2] << "]";
  return o.str();
}

// FNV-1a (64 bits) of the bytes of `file`, continued from `hash`; false if it cannot be read.
bool hash_file(const std::filesystem::path& file, uint64_t& hash) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  for (std::istreambuf_iterator<char> it(in), end; it != end; ++it) {
    hash ^= static_cast<unsigned char>(*it);
    hash *= 0x100000001b3ULL;
  }
  return true;
}

}  // namespace

std::string mesh_key(const std::filesystem::path& mesh_file) {
  uint64_t hash = 0xcbf29ce484222325ULL;
  bool read = hash_file(mesh_file, hash);
  if (read && mesh_file.extension() == ".node") read = hash_file(tetgen_element_file(mesh_file), hash);
  std::string key = mesh_file.filename().string() + "#";
  if (!read) return key + "unread";
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(hash));
  return key + hex;
}

Eigen::Vector2d top_face_centre(const Scene& scene) {
  return 0.5 * (scene.box.min.head<2>() + scene.box.max.head<2>());
}

bool at_top_face_centre(const Scene& scene, const Eigen::Vector2d& site) {
  const double edge = (scene.box.max - scene.box.min).head<2>().maxCoeff();
  return (site - top_face_centre(scene)).cwiseAbs().maxCoeff() <= 1e-9 * edge;
}

Eigen::Vector2d indenter_site(const Scene& scene) {
  return scene.indenter.position_given ? Eigen::Vector2d(scene.indenter.position.head<2>()) : top_face_centre(scene);
}

std::string reference_key(const Scene& scene) {
  std::ostringstream o;
  o.precision(12);
  // The body: its box, or a mesh body without one by its file (any shape: the box would be the
  // unused default). A mesh of a box that the scene gives shares the box's reference.
  if (scene.box_given || scene.distribution.type != DistributionType::mesh)
    o << "box=" << vec_text(scene.box.min) << vec_text(scene.box.max);
  else
    o << "mesh=" << mesh_key(scene.distribution.mesh_file);
  o << " E=" << scene.material.young_modulus
    << " nu=" << scene.material.poisson_ratio;
  // A heterogeneous body is another problem (a homogeneous body's key is unchanged).
  for (const InclusionSpec& inc : scene.material.inclusions) {
    if (inc.shape == InclusionShape::group)
      o << " group=" << inc.group;
    else if (inc.shape == InclusionShape::sphere)
      o << " sphere=" << vec_text(inc.center) << inc.radius;
    else
      o << " inclusion_box=" << vec_text(inc.min) << vec_text(inc.max);
    o << ",E=" << inc.young_modulus << ",nu=" << inc.poisson_ratio;
  }
  o << " fixed=" << scene.fixed_faces;
  for (const FixedRegion& f : scene.fixed_regions)  // (none in the stored references: their keys stay)
    o << "+" << static_cast<int>(f.kind) << ":" << f.group << vec_text(f.point) << vec_text(f.normal) << f.tolerance
      << vec_text(f.min) << vec_text(f.max) << vec_text(f.center) << f.radius;
  o << " R=" << scene.indenter.radius << " site=";
  const Eigen::Vector2d site = indenter_site(scene);
  if (at_top_face_centre(scene, site))
    o << "centre";
  else
    o << "[" << site[0] << "," << site[1] << "]";
  return o.str();
}

std::string large_strain_reference_key(const Scene& scene) {
  return reference_key(scene) + " law=neo_hookean held";
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
      if (l.contains("forces")) level.forces = l.at("forces").get<std::vector<double>>();
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
