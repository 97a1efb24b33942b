// Local refinement of a tetrahedral mesh by longest-edge bisection (core/mesh_refinement.h):
// judged by what any conforming refinement of the same body must satisfy (the volume, the
// boundary's area and faces, each interior face shared by two tetrahedra of opposite
// orientation), by the sizes it promised, and by its independence of anything but the base
// and the focus.
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <unistd.h>

#include "analysis/reference.h"
#include "analysis/rest.h"
#include "core/model.h"
#include "core/options.h"
#include "core/reference_file.h"
#include "core/state.h"

#include "core/mesh_reader.h"
#include "core/mesh_refinement.h"
#include "core/node_cloud.h"
#include "core/resolution.h"
#include "core/scene.h"
#include "test_util.h"

namespace palpate {
namespace {

namespace fs = std::filesystem;
const fs::path kBaseMesh = fs::path(PALPATE_SOURCE_DIR) / "scenes" / "meshes" / "palpation_block_base.msh";

const TetMesh& base_mesh() {
  static const TetMesh mesh = read_mesh(kBaseMesh);
  return mesh;
}

double tet_volume(const Points& X, const std::array<int, 4>& t) {
  const Vec3 a = X.col(t[0]);
  return (X.col(t[1]) - a).dot((X.col(t[2]) - a).cross(X.col(t[3]) - a)) / 6.0;
}

MeshRefinement spec_at(double x, double y) {
  MeshRefinement spec;
  spec.focus = Vec3(x, y, 0.0);
  spec.focus_size = 0.0012;
  spec.growth = 1.2;
  return spec;
}

TEST(MeshRefinement, KeepsTheBodyAndConforms) {
  const TetMesh& base = base_mesh();
  const TetMesh fine = refine_mesh(base, spec_at(0.0175, -0.01));
  ASSERT_GT(fine.positions.cols(), base.positions.cols());
  // The base's vertices keep their places and indices.
  EXPECT_TRUE(fine.positions.leftCols(base.positions.cols()) == base.positions);
  // Every tetrahedron positive; their volumes add up to the box's (0.1 x 0.1 x 0.05 m).
  double total = 0;
  for (const auto& t : fine.tetrahedra) {
    const double v = tet_volume(fine.positions, t);
    ASSERT_GT(v, 0.0);
    total += v;
  }
  EXPECT_NEAR(total, 5e-4, 1e-12 * 5e-4);
  EXPECT_NEAR(fine.total_volume, 5e-4, 1e-12 * 5e-4);
  double lumped = 0;
  for (double v : fine.nodal_volume) lumped += v;
  EXPECT_NEAR(lumped, 5e-4, 1e-12 * 5e-4);
  // Conforming: a face belongs to one tetrahedron (the boundary) or to two, which see it with
  // opposite orientations; a hanging node would leave faces that match nothing inside.
  std::map<std::array<int, 3>, std::vector<int>> faces;  // sorted face -> orientation signs
  for (const auto& t : fine.tetrahedra)
    for (int skip = 0; skip < 4; ++skip) {
      std::array<int, 3> f{};
      int k = 0;
      for (int a = 0; a < 4; ++a)
        if (a != skip) f[k++] = t[a];
      // The orientation of the face seen from its tetrahedron: the parity of the sort.
      int swaps = 0;
      for (int i = 0; i < 3; ++i)
        for (int j = i + 1; j < 3; ++j) swaps += f[i] > f[j];
      std::sort(f.begin(), f.end());
      faces[f].push_back((swaps + skip) % 2);
    }
  size_t boundary = 0;
  double area = 0;
  for (const auto& [f, signs] : faces) {
    ASSERT_LE(signs.size(), 2u);
    if (signs.size() == 2) {
      EXPECT_NE(signs[0], signs[1]);
      continue;
    }
    ++boundary;
    const Vec3 a = fine.positions.col(f[0]), b = fine.positions.col(f[1]), c = fine.positions.col(f[2]);
    area += 0.5 * (b - a).cross(c - a).norm();
    // On one of the box's faces.
    const bool on_box = (std::abs(a.x() - b.x()) + std::abs(a.x() - c.x()) == 0 && std::abs(std::abs(a.x()) - 0.05) < 1e-12) ||
                        (std::abs(a.y() - b.y()) + std::abs(a.y() - c.y()) == 0 && std::abs(std::abs(a.y()) - 0.05) < 1e-12) ||
                        (a.z() == b.z() && a.z() == c.z() && (a.z() == 0.0 || std::abs(a.z() + 0.05) < 1e-12));
    EXPECT_TRUE(on_box) << "a boundary face off the box at (" << a.transpose() << ")";
  }
  EXPECT_EQ(boundary, fine.boundary_faces.size());
  EXPECT_NEAR(area, 2 * 0.01 + 4 * 0.005, 1e-12);
}

TEST(MeshRefinement, ReachesTheAskedSizeOnlyNearTheFocus) {
  const TetMesh& base = base_mesh();
  const MeshRefinement spec = spec_at(-0.02, 0.03);
  const TetMesh fine = refine_mesh(base, spec);
  // Every tetrahedron's mean edge within (7.1) at its centroid; the tetrahedra at the focus
  // near focus_size.
  double nearest_mean = INFINITY, nearest_distance = INFINITY;
  for (const auto& t : fine.tetrahedra) {
    Vec3 centroid = Vec3::Zero();
    double mean = 0;
    for (int a = 0; a < 4; ++a) {
      centroid += 0.25 * fine.positions.col(t[a]);
      for (int b = a + 1; b < 4; ++b) mean += (fine.positions.col(t[a]) - fine.positions.col(t[b])).norm() / 6;
    }
    const double r = (centroid - spec.focus).norm();
    ASSERT_LE(mean, refinement_size(spec, r) * (1 + 1e-12));
    if (r < nearest_distance) {
      nearest_distance = r;
      nearest_mean = mean;
    }
  }
  EXPECT_GT(nearest_mean, 0.25 * spec.focus_size);  // bisection halves edges at most once too often
  // Without max_size (7.1) refines the far field too (the base's 15 mm tetrahedra at the
  // bottom exceed h there); with it, the new vertices gather near the focus: (7.1) reaches
  // 3 mm at r = 9 mm. The bisections that keep the mesh conforming (a neighbour's longest
  // edge first) may run farther along the base's longer edges into the interior (up to 52 mm
  // measured here, by a wall), but they are few (88 of 770 beyond 20 mm).
  const Eigen::Index added = fine.positions.cols() - base.positions.cols();
  MeshRefinement local = spec;
  local.max_size = 0.003;
  const TetMesh near = refine_mesh(base, local);
  const Eigen::Index added_near = near.positions.cols() - base.positions.cols();
  EXPECT_LT(2 * added_near, added);  // measured: 770 against 1895
  int beyond = 0;
  for (Eigen::Index i = base.positions.cols(); i < near.positions.cols(); ++i)
    beyond += (near.positions.col(i) - spec.focus).norm() > 0.02;
  EXPECT_LT(beyond, added_near / 5) << beyond << " of " << added_near << " new vertices beyond 20 mm";
}

TEST(MeshRefinement, DependsOnlyOnTheBaseAndTheFocus) {
  const TetMesh& base = base_mesh();
  const TetMesh a = refine_mesh(base, spec_at(0.01, 0.01));
  const TetMesh b = refine_mesh(base, spec_at(0.01, 0.01));
  EXPECT_TRUE(a.positions == b.positions);
  EXPECT_TRUE(a.tetrahedra == b.tetrahedra);
  // Refocusing elsewhere and back gives the same mesh: refinement always starts from the base.
  const TetMesh elsewhere = refine_mesh(base, spec_at(-0.03, 0.0));
  EXPECT_NE(elsewhere.positions.cols(), 0);
  const TetMesh back = refine_mesh(base, spec_at(0.01, 0.01));
  EXPECT_TRUE(a.positions == back.positions);
}

TEST(MeshRefinement, MidpointsJoinTheSurfaceGroupsOfTheirFaces) {
  // A mesh with named surface groups: the dome's (base: the flat face z = 0, skin: the curved one).
  const TetMesh dome = read_mesh(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "meshes" / "palpation_dome.msh");
  ASSERT_FALSE(dome.surface_groups.empty());
  double top = -INFINITY;
  for (Eigen::Index i = 0; i < dome.positions.cols(); ++i) top = std::max(top, dome.positions(2, i));
  MeshRefinement spec;
  spec.focus = Vec3(0, 0, top);
  spec.focus_size = 0.5 * (dome.positions.col(dome.tetrahedra[0][0]) - dome.positions.col(dome.tetrahedra[0][1])).norm();
  spec.growth = 1.2;
  const TetMesh fine = refine_mesh(dome, spec);
  ASSERT_GT(fine.positions.cols(), dome.positions.cols());
  // A group's new members are midpoints of its own boundary edges: the base group's stay on z = 0.
  for (size_t g = 0; g < fine.surface_groups.size(); ++g) {
    const auto& group = fine.surface_groups[g];
    ASSERT_EQ(group.name, dome.surface_groups[g].name);
    EXPECT_GE(group.nodes.size(), dome.surface_groups[g].nodes.size());
    if (group.name == "base") {
      for (int v : group.nodes) EXPECT_EQ(fine.positions(2, v), 0.0);
    }
  }
  // Every boundary vertex belongs to some group (the dome's boundary is base + skin).
  std::vector<uint8_t> grouped(fine.positions.cols(), 0);
  for (const auto& group : fine.surface_groups)
    for (int v : group.nodes) grouped[v] = 1;
  for (const auto& f : fine.boundary_faces)
    for (int v : f) EXPECT_TRUE(grouped[v]) << "boundary vertex " << v << " in no group";
}

TEST(MeshRefinement, NewSurfaceVerticesLieOnTheCurvedSurfaceNotOnItsFacets) {
  // The dome's coarse base (skin facets about 3 mm on a sphere of radius 5 cm) refined to 1 mm
  // toward a point of its flank: a new vertex of the skin on the facet's chord would sit up to
  // a facet's sag, h^2 / (8 R_b), inside the sphere; on the Hermite curve of (7.1a) it is on the
  // sphere to fourth order in h. The truth is the sphere |x| = R_b the base was meshed on.
  const double RB = 0.05;
  const TetMesh base = read_mesh(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "meshes" / "palpation_dome_base.msh");
  const auto skin = std::find_if(base.surface_groups.begin(), base.surface_groups.end(),
                                 [](const SurfaceGroup& g) { return g.name == "skin"; });
  ASSERT_NE(skin, base.surface_groups.end());
  double base_error = 0, sag = 0;  // the base's own vertices, and its largest facet's sag
  for (int v : skin->nodes) base_error = std::max(base_error, std::abs(base.positions.col(v).norm() - RB));
  for (const auto& f : base.boundary_faces)
    for (int k = 0; k < 3; ++k) {
      const Vec3 a = base.positions.col(f[k]), b = base.positions.col(f[(k + 1) % 3]);
      if (a[2] > 0 && b[2] > 0) sag = std::max(sag, (b - a).squaredNorm() / (8 * RB));
    }
  ASSERT_GT(sag, 1e-5);
  MeshRefinement spec;
  spec.focus = Vec3(0.02, 0.01, std::sqrt(RB * RB - 0.02 * 0.02 - 0.01 * 0.01));
  spec.focus_size = 0.001;
  spec.growth = 1.2;
  const TetMesh fine = refine_mesh(base, spec);
  const int n0 = static_cast<int>(base.positions.cols());
  int new_skin = 0;
  double worst = 0;
  for (const auto& g : fine.surface_groups) {
    if (g.name != "skin") continue;
    for (int v : g.nodes)
      if (v >= n0 && fine.positions(2, v) > 0) {  // (the rim's midpoints stay on the base plane: a crease)
        ++new_skin;
        worst = std::max(worst, std::abs(fine.positions.col(v).norm() - RB));
      }
  }
  ASSERT_GT(new_skin, 50);
  std::printf("new skin vertices %d: off the sphere by at most %.3g m (the base %.3g m, its largest sag %.3g m)\n", new_skin, worst, base_error, sag);
  EXPECT_LT(worst, base_error + 0.01 * sag) << new_skin << " new skin vertices; the base's largest sag " << sag;
  // Still a valid mesh: every tetrahedron positive, the volume between the base's (its facets)
  // and the hemisphere's.
  for (const auto& t : fine.tetrahedra) EXPECT_GT(tet_volume(fine.positions, t), 0.0);
  const double hemisphere = 2.0 / 3.0 * M_PI * RB * RB * RB;
  EXPECT_GT(fine.total_volume, base.total_volume);
  EXPECT_LT(fine.total_volume, hemisphere);
}

TEST(MeshRefinement, RefusesWhatCannotBeMeant) {
  MeshRefinement spec = spec_at(0, 0);
  spec.focus_size = 0;
  EXPECT_THROW(refine_mesh(base_mesh(), spec), std::invalid_argument);
  spec = spec_at(0, 0);
  spec.growth = 1.0;
  EXPECT_THROW(refine_mesh(base_mesh(), spec), std::invalid_argument);
  spec = spec_at(NAN, 0);
  EXPECT_THROW(refine_mesh(base_mesh(), spec), std::invalid_argument);
}

TEST(MeshRefinement, NearestBoundaryPointIsOnTheSurface) {
  // Above the block: straight down onto the top face; beside it: onto the side.
  EXPECT_TRUE(nearest_boundary_point(base_mesh(), Vec3(0.01, -0.02, 0.03)).isApprox(Vec3(0.01, -0.02, 0.0), 1e-12));
  EXPECT_TRUE(nearest_boundary_point(base_mesh(), Vec3(0.07, 0.0, -0.02)).isApprox(Vec3(0.05, 0.0, -0.02), 1e-12));
}

TEST(MeshRefinement, SceneRefinesTowardTheTool) {
  // The scene's refine object: the cloud follows indenter.position (nearest surface point).
  const fs::path scene_file = fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_block_follow.json";
  Scene scene = load_scene(scene_file);
  const NodeCloud at_centre = make_node_cloud(scene);
  scene.indenter.position_given = true;
  scene.indenter.position = Vec3(0.02, 0.02, 0.011);
  const NodeCloud at_site = make_node_cloud(scene);
  MeshRefinement spec = spec_at(0.02, 0.02);
  spec.focus_size = scene.distribution.refine.size;
  spec.max_size = scene.distribution.refine.max_size;
  const TetMesh direct = refine_mesh(base_mesh(), spec);
  EXPECT_TRUE(at_site.positions == direct.positions);
  EXPECT_NE(at_centre.positions.cols(), 0);
  // Without a size the refinement takes the spacing the scene asks for (core/resolution.h):
  // a third of the Hertz contact radius at the smallest verification force (0.86 mm here).
  const Scene derived = parse_scene(R"({"body": {"box": {"min": [-0.05, -0.05, -0.05], "max": [0.05, 0.05, 0]},
                                                  "distribution": {"type": "mesh", "file": ")" + kBaseMesh.string() + R"(",
                                                                   "refine": {"growth": 1.3}}},
                                         "mls": {"volumes": "mesh"},
                                         "material": {"young_modulus": 2e4, "poisson_ratio": 0.3},
                                         "indenter": {"radius": 0.01},
                                         "verify": {"forces": [0.05, 0.262]}})",
                                    "derived.json", ".");
  EXPECT_NEAR(derived.distribution.refine.size, 0.00086, 0.00001);
  EXPECT_EQ(derived.distribution.refine.growth, 1.3);
}

}  // namespace
}  // namespace palpate

namespace palpate {
namespace {

// The scene's model pressed to rest on the vertical guide at the smallest and the largest
// force of its verification sweep, each depth within `tolerance` (3.5 %) of the reference's
// (the map's site (x, y), m).
void press_against(const Scene& scene, const Reference& reference, double x, double y, double tolerance = 0.035) {
  const Model model = build_model(scene);
  Options opt = options_of(scene);
  opt.tool_guide = ToolGuide::vertical;
  State state = make_state(model, opt);
  for (double F : {scene.verify.forces.front(), scene.verify.forces.back()}) {
    const PressResult press = press_to_rest(model, opt, scene.verify.rest, state, F);
    ASSERT_TRUE(press.at_rest) << "site (" << x << ", " << y << "), " << F << " N";
    const double d = indentation_at_tool(model, state), d_ref = reference_indentation(reference, F);
    std::printf("%s at (%g, %g) mm, %g N: %+.2f %%\n", scene.name.c_str(), 1e3 * x, 1e3 * y, F, 100 * (d - d_ref) / d_ref);
    EXPECT_NEAR(d, d_ref, tolerance * d_ref) << "site (" << x << ", " << y << "), " << F << " N: "
                                              << 100 * (d - d_ref) / d_ref << " %";
  }
}

// A site nothing was prepared for: drawn (seeded) from the 25 sites of the surface map, the
// follow scene's cloud refined there by the scene itself, pressed to rest on the vertical
// guide at the smallest and the largest verification force, against that site's converged
// finite-block reference (the hex FEM, data/verification/surface_map/references; a site off
// the octant takes its mirror's, the block being symmetric under x -> -x, y -> -y, x <-> y).
// The map measured 0.9 ... 3.2 % worst over the 25 sites.
TEST(MeshRefinement, AnUnanticipatedSiteIsOnItsReference) {
  std::mt19937 draw(32);
  const double grid[5] = {-0.035, -0.0175, 0.0, 0.0175, 0.035};
  const double x = grid[draw() % 5], y = grid[draw() % 5];
  double a = std::abs(x), b = std::abs(y);
  if (a < b) std::swap(a, b);
  auto text = [](double v) {
    std::ostringstream s;
    s << v;
    return s.str();
  };
  const fs::path reference_file =
      a == 0.0 ? fs::path(PALPATE_SOURCE_DIR) / "scenes" / "references" / "palpation_block.json"
               : fs::path(PALPATE_SOURCE_DIR) / "data" / "verification" / "surface_map" / "references" /
                     ("palpation_block_site_" + text(a) + "_" + text(b) + ".json");
  Scene scene = load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_block_follow.json");
  place_indenter_at_site(scene, x, y);
  press_against(scene, load_reference(reference_file), x, y);
}

// Another tool, another material, another sweep, and no cloud made for them: the follow
// scene with a 5 mm tool (not 10), a nearly incompressible neo-Hookean tissue (nu 0.45, not a
// corotational 0.3) and forces of 0.02 ... 0.15 N, its refinement's size left to the scene
// (three spacings across the smallest force's contact radius: 0.48 mm, core/resolution.h), at
// the stable step of that spacing. Against the large-strain reference of the same block, law
// and tool (neo-Hookean bricks, the tool held: a different method; palpate-reference --depths,
// uncertain by 0.9 ... 1.7 %, data/verification/surface_map/references), within the issue's
// 2 % at the smallest force as at the largest (measured +0.5 and -1.0 %; with the 10 mm tool's
// 1 mm refinement +0.9 and +0.7 %). The corotational law at nu 0.45, another law, is +4.2 and
// +7.2 % against this reference and would fail here.
TEST(MeshRefinement, AnotherToolAndANearlyIncompressibleTissueNeedNoCloudMadeForThem) {
  const Scene scene = load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_block_follow.json",
                                 {{"indenter.radius", "0.005"},
                                  {"material.poisson_ratio", "0.45"},
                                  {"material.law", "\"neo_hookean\""},
                                  {"body.distribution.refine", R"({"growth": 1.2, "max_size": 0.0035})"},
                                  {"integrator.dt", "0.00025"},
                                  {"verify.forces", "[0.02, 0.05, 0.1, 0.15]"}});
  const Reference reference = load_reference(fs::path(PALPATE_SOURCE_DIR) / "data" / "verification" / "surface_map" /
                                             "references" / "palpation_block_r5_nu0.45_neo_hookean.json");
  EXPECT_EQ(reference.key, large_strain_reference_key(scene));
  EXPECT_NEAR(scene.distribution.refine.size, required_resolution(scene).contact_spacing, 1e-12);
  // Under the sanitizers the presses took 85 s; what they run (a cloud refined in-process,
  // its model, a press to rest) AnUnanticipatedSiteIsOnItsReference runs there too.
  if (test::kSanitized) GTEST_SKIP() << "the presses at 0.48 mm run in the Release suite";
  press_against(scene, reference, 0.0, 0.0, 0.02);
}

}  // namespace
}  // namespace palpate

namespace palpate {
namespace {

// `in` (gmsh 4.1 ASCII, non-parametric nodes) with every node moved by Q, written to `out`.
void write_rotated_mesh(const fs::path& in, const fs::path& out, const Mat3& Q) {
  std::ifstream file(in);
  std::ofstream rotated(out);
  rotated.precision(17);
  std::string line;
  auto copy = [&] {
    if (!std::getline(file, line)) throw std::runtime_error(in.string() + ": ends early");
    rotated << line << "\n";
  };
  while (std::getline(file, line) && line != "$Nodes") rotated << line << "\n";
  rotated << line << "\n";
  copy();
  std::istringstream header(line);
  int blocks = 0;
  header >> blocks;
  for (int b = 0; b < blocks; ++b) {
    copy();
    std::istringstream block(line);
    int dim = 0, tag = 0, parametric = 0, n = 0;
    block >> dim >> tag >> parametric >> n;
    ASSERT_EQ(parametric, 0);
    for (int k = 0; k < n; ++k) copy();  // the node tags
    for (int k = 0; k < n; ++k) {
      std::getline(file, line);
      std::istringstream xyz(line);
      Vec3 x;
      xyz >> x[0] >> x[1] >> x[2];
      const Vec3 y = Q * x;
      rotated << y[0] << " " << y[1] << " " << y[2] << "\n";
    }
  }
  while (std::getline(file, line)) rotated << line << "\n";
}

// The dome's version of the test above, on its surface map (scripts/surface_map_study.sh
// --dome): a site drawn (seeded) from the map's 25, the dome rotated about its centre so that
// the site is its top (pressed along the skin's normal, as the map presses it; the lump turns
// with it), its cloud refined there by the scene itself, against the converged reference of
// the dome rotated to that site's polar angle (data/verification/surface_map/references; the
// hemisphere fixed on its base and its lump on the axis are the same problem at every azimuth).
TEST(MeshRefinement, AnUnanticipatedSiteOfTheDomeIsOnItsReference) {
  std::mt19937 draw(32);
  const double grid[5] = {-0.025, -0.0125, 0.0, 0.0125, 0.025};
  const double x = grid[draw() % 5], y = grid[draw() % 5], RB = 0.05;
  const Vec3 site(x, y, std::sqrt(RB * RB - x * x - y * y));
  const Mat3 Q = Eigen::Quaterniond::FromTwoVectors(site.normalized(), Vec3::UnitZ()).toRotationMatrix();
  const fs::path dir = fs::temp_directory_path() / ("palpate_dome_site_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  write_rotated_mesh(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "meshes" / "palpation_dome_base.msh",
                     dir / "palpation_dome_base.msh", Q);
  Scene scene = load_scene(fs::path(PALPATE_SOURCE_DIR) / "scenes" / "palpation_dome_follow.json",
                           {{"body.distribution.file", "\"" + (dir / "palpation_dome_base.msh").string() + "\""}});
  for (InclusionSpec& inclusion : scene.material.inclusions) inclusion.center = Q * inclusion.center;
  place_indenter_at_site(scene, 0.0, 0.0);
  std::ostringstream r;  // as the study names it (%.10g)
  r.precision(10);
  r << std::hypot(x, y);
  const Reference reference = load_reference(fs::path(PALPATE_SOURCE_DIR) / "data" / "verification" / "surface_map" /
                                             "references" / ("palpation_dome_follow_site_" + r.str() + "_0.json"));
  press_against(scene, reference, x, y);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace palpate
