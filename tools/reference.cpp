// palpate-reference: the converged finite-block reference of a scene (analysis/reference.h):
// the linear hex FEM on graded lattices refined level by level, solved exactly and
// quasi-statically, with Richardson extrapolation of the indentation at each force; or, for
// bodies of any shape, the same on linear tetrahedra of a family of meshes (--tet-meshes,
// analysis/tet_reference.h).
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "cli/arguments.h"
#include "core/hertz.h"
#include "analysis/reference.h"
#include "analysis/tet_reference.h"
#include "core/scene.h"

#include <spdlog/spdlog.h>

using namespace palpate;

namespace {

const char* kUsage = R"(usage: palpate-reference --scene FILE [options]
  --scene FILE          scene file; its box, material, fixed faces and indenter are used
  --forces F1,F2,...    forces in N (default: the scene's verify.forces, or the Hertz
                        depths d/R = 0.02 ... 0.2)
  --levels N1,N2,...    nodes per edge of the graded lattices, coarse to fine
                        (default 17,25,33,41; at least three)
  --first-spacing S     first spacing (m) of the 21-per-edge member of the family (default 0.025)
  --site X,Y            the site (m) on the top face (default: the scene's indenter.position
                        (x, y), else the centre); every level is graded toward it and
                        the key names it; refused off the face or closer than R to a wall
  --depths D1,D2,...    the large-strain reference instead (docs/physics.md, "The
                        large-strain reference"): neo-Hookean bricks on the graded lattices
                        (--levels; default 17,21,25,29), the tool held at each depth
                        (m, increasing) below first touch at the centre, Richardson on the
                        force; for palpate-verify --reference FILE on neo-Hookean scenes;
                        inclusions must be spheres or boxes centred on the tool's axis
  --core-half-width W   with --depths: the quarter-block family instead (docs/physics.md §5):
                        a quarter of the block with mirror planes through the site, each
                        axis uniform over W (m) from the site with --core-share of its
                        intervals (default 0.6), geometric beyond; --levels are the
                        quarter's nodes per axis (choose W above the largest contact radius)
  --core-share S        the share of each axis's intervals inside the core (0 < S < 1)
  --tet-meshes F1:H1,F2:H2,...
                        the reference of a body of any shape instead (docs/physics.md §5,
                        "A reference for any shape"): linear tetrahedra on these meshes of
                        the scene's body (coarse to fine, at least three; H the element size
                        at the site, m), the exact static solve on each, Richardson in H
  --set KEY=VALUE       override a scene field (repeatable)
  --out FILE            write the reference as JSON (what palpate-verify --reference reads)
  --json                print the reference as JSON on stdout
  --key                 print only the key the reference would have (the scene's body,
                        material, fixed regions, tool radius and site) and exit; computes nothing
  --quiet               no progress on stderr
  --log-level LEVEL     spdlog level (default: warn; debug: the held solve's Newton steps)
)";

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file, out_file;
  SceneOverrides overrides;
  std::vector<double> forces, depths;
  ReferenceOptions options;
  LargeStrainLattice lattice;
  bool levels_given = false;
  bool json = false, quiet = false, key_only = false;
  std::string log_level = "warn";
  std::vector<double> site;
  std::vector<TetMeshLevel> tet_meshes;
  try {
    for (cli::Arguments args(argc, argv); args.next();) {
      const std::string& arg = args.flag();
      auto value = [&] { return args.value(); };
      if (arg == "--scene") scene_file = value();
      else if (arg == "--forces") forces = cli::positive_list(value(), "--forces");
      else if (arg == "--levels") options.levels = cli::positive_list<int>(value(), "--levels"), levels_given = true;
      else if (arg == "--first-spacing") options.base_first_spacing = cli::positive_list(value(), "--first-spacing").at(0);
      else if (arg == "--set") overrides.push_back(cli::scene_override(value()));
      else if (arg == "--depths") depths = cli::positive_list(value(), "--depths");
      else if (arg == "--core-half-width")
        lattice.core_half_width = cli::positive_list(value(), "--core-half-width").at(0);
      else if (arg == "--core-share") {
        lattice.core_share = cli::positive_list(value(), "--core-share").at(0);
        if (!(lattice.core_share < 1)) throw std::invalid_argument("--core-share: a share below 1");
      }
      else if (arg == "--tet-meshes") {
        std::stringstream list(value());
        for (std::string item; std::getline(list, item, ',');) {
          const size_t colon = item.rfind(':');
          if (colon == std::string::npos || colon == 0)
            throw std::invalid_argument("--tet-meshes: '" + item + "' is not FILE:H (H the element size at the site, m)");
          const double h = cli::positive_list(item.substr(colon + 1), "--tet-meshes").at(0);
          tet_meshes.push_back({item.substr(0, colon), h});
        }
        if (tet_meshes.size() < 3) throw std::invalid_argument("--tet-meshes: at least three meshes");
      }
      else if (arg == "--out") out_file = value();
      else if (arg == "--site") {
        site = cli::number_list(value(), "--site");
        if (site.size() != 2) throw std::invalid_argument("--site: expected X,Y (two numbers, m)");
      }
      else if (arg == "--json") json = true;
      else if (arg == "--key") key_only = true;
      else if (arg == "--quiet") quiet = true;
      else if (arg == "--log-level") log_level = value();
      else if (arg == "--help" || arg == "-h") {
        std::cout << kUsage;
        return 0;
      } else throw std::invalid_argument("unknown option " + arg);
    }
    if (scene_file.empty()) throw std::invalid_argument("--scene FILE is required");
    if (!depths.empty() && options.base_first_spacing > 0)
      throw std::invalid_argument("--first-spacing: not used with --depths (see --core-half-width)");
    if (!tet_meshes.empty() && (!depths.empty() || levels_given || options.base_first_spacing > 0))
      throw std::invalid_argument("--tet-meshes: not with --depths, --levels or --first-spacing");
    if (depths.empty() && lattice.core_half_width > 0)
      throw std::invalid_argument("--core-half-width: only with --depths");
    if (options.levels.size() < 3) throw std::invalid_argument("--levels: at least three levels");
    for (size_t k = 1; k < options.levels.size(); ++k)
      if (options.levels[k] <= options.levels[k - 1]) throw std::invalid_argument("--levels must increase");
  } catch (const std::exception& e) {
    std::cerr << "palpate-reference: " << e.what() << "\n\n" << kUsage;
    return 2;
  }

  spdlog::set_level(spdlog::level::from_str(log_level));
  Reference ref;
  try {
    Scene scene = load_scene(scene_file, overrides);
    if (!site.empty())
      place_indenter_at_site(scene, site[0], site[1], "--site");
    else if (tet_meshes.empty())
      check_site(scene, scene_file + ": /indenter/position");
    if (key_only) {
      std::cout << (depths.empty() ? reference_key(scene) : large_strain_reference_key(scene)) << "\n";
      return 0;
    }
    const double R = scene.indenter.radius;
    const double E_star = hertz::effective_modulus(scene.material.young_modulus, scene.material.poisson_ratio);
    if (forces.empty()) forces = scene.verify.forces;
    if (forces.empty())
      for (int k = 1; k <= 10; ++k) forces.push_back(hertz::force(0.01 * k, scene.indenter.radius, E_star));
    const auto progress = [&](const std::string& m) {
      if (!quiet) std::fprintf(stderr, "palpate-reference: %s\n", m.c_str());
    };
    if (!tet_meshes.empty())
      ref = tet_mesh_reference(scene, forces, tet_meshes, progress);
    else if (!depths.empty())
      ref = large_strain_reference(scene, depths, levels_given ? options.levels : std::vector<int>{17, 21, 25, 29},
                                   progress, lattice);
    else
      ref = finite_cube_reference(scene, forces, options, progress);
    if (!out_file.empty()) {
      std::ofstream out(out_file);
      out << reference_to_json(ref) << "\n";
      if (!out) throw std::runtime_error("cannot write " + out_file);
    }
    if (json) {
      std::cout << reference_to_json(ref) << "\n";
      return 0;
    }
    if (!depths.empty()) {
      std::printf("\nLarge-strain reference (neo-Hookean hex FEM, graded lattices, tool held, Richardson on F): %s\n",
                  ref.key.c_str());
      std::printf("%10s", "d [m]");
      for (const auto& l : ref.levels) std::printf(" %9d^3", l.per_edge);
      std::printf(" %11s %10s %6s %10s\n", "F* [N]", "+- d [m]", "p", "F_Hertz");
      for (size_t k = 0; k < ref.forces.size(); ++k) {
        std::printf("%10.4f", ref.indentation[k]);
        for (const auto& l : ref.levels) std::printf(" %11.4f", l.forces[k]);
        std::printf(" %11.4f %10.2e %6.2f %10.4f\n", ref.forces[k], ref.uncertainty[k], ref.order[k],
                    hertz::force(ref.indentation[k], R, E_star));
      }
      return 0;
    }
    if (tet_meshes.empty())
      std::printf("\nFinite-block reference (linear hex FEM, graded lattices, Richardson): %s\n", ref.key.c_str());
    else
      std::printf("\nReference (linear tetrahedra, meshes refined at the site, Richardson): %s\n", ref.key.c_str());
    std::printf("%10s", "F [N]");
    for (const auto& l : ref.levels)
      if (l.per_edge > 0)
        std::printf(" %9d^3", l.per_edge);
      else
        std::printf(" %9.2gmm", l.first_spacing * 1e3);
    std::printf(" %11s %10s %6s %10s\n", "d* [m]", "+- [m]", "p", "d_Hertz");
    for (size_t f = 0; f < ref.forces.size(); ++f) {
      std::printf("%10.3f", ref.forces[f]);
      for (const auto& l : ref.levels) std::printf(" %11.6f", l.indentation[f]);
      std::printf(" %11.6f %10.2e %6.2f %10.6f\n", ref.indentation[f], ref.uncertainty[f], ref.order[f],
                  hertz::depth(ref.forces[f], R, E_star));
    }
  } catch (const std::exception& e) {
    std::cerr << "palpate-reference: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
