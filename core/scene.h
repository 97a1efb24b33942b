#pragma once
// Scene description: plain structs filled from a JSON scene file
// (docs/scene-format.md lists every field). The defaults are the paper's set-up
// (docs/physics.md §4) except where a default must be neutral
// (no damping, no gravity, kernel volumes); scenes/hertz_cube.json writes the
// verification set-up out in full. Only what a scene names is built and computed.
#include <cstdint>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/types.h"

namespace palpate {

// Thrown for a malformed or out-of-range scene. what() names the source (file),
// the field (JSON pointer, e.g. "/material/poisson_ratio") and the reason.
class SceneError : public std::runtime_error {
 public:
  SceneError(const std::string& source, const std::string& field, const std::string& reason);
  const std::string& source() const { return source_; }
  const std::string& field() const { return field_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string source_, field_, reason_;
};

// The elastic model of the body (scene "model"): the meshless solid, or the hexahedral FEM
// reference (docs/physics.md §5).
enum class SolidKind { mls, hex_fem };
enum class DistributionType { grid, jittered_grid, graded_grid, node_file, mesh };
// kernel sums, lattice cell volumes, or a quarter of each incident tetrahedron (mesh clouds)
enum class VolumeRule { kernel, lattice, mesh };
// Support radius h_i = alpha * (the mean distance to the k neighbours | the k-th neighbour's distance).
enum class SupportRule { mean_distance, kth_distance };
// Nodal integration of the MLS gradients as is, or corrected to satisfy the
// integration constraint sum_i v_i g_ij = 0 at interior nodes (consistent_integration.h).
enum class IntegrationRule { nodal, consistent };
enum class IntegratorType { rk4, symplectic_euler, implicit_euler };
// How the tool is held: on a vertical guide (it moves along z only, as the indenter of
// the Hertz experiment: lateral contact forces are taken by the guide), or free in all
// three translations (a haptic device's end effector).
enum class ToolGuide { vertical, free };
// The MLS solid's material law: St Venant-Kirchhoff (A-4, A-5, the paper's), or the
// corotational linear law psi = mu |F - R|^2 + lambda/2 (tr(R^T F) - 3)^2 (F = R U), or the
// small-strain linear law (a verification law: the continuum of the linear hex FEM), or the
// compressible neo-Hookean law psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2 (MLS only).
enum class MaterialLaw { stvk, corotational, linear, neo_hookean };

// Faces of the body's box, as bits of Scene::fixed_faces.
enum Face : uint32_t {
  face_x_min = 1u << 0,
  face_x_max = 1u << 1,
  face_y_min = 1u << 2,
  face_y_max = 1u << 3,
  face_bottom = 1u << 4,  // z_min
  face_top = 1u << 5,     // z_max
  faces_sides = face_x_min | face_x_max | face_y_min | face_y_max,
};

// A region of particles held fixed besides the box faces (a `fixed` element that is an
// object, docs/scene-format.md): a mesh's physical surface group (its nodes), the
// particles within `tolerance` of a plane, or inside a box or a sphere.
enum class FixedRegionKind { group, plane, box, sphere };
struct FixedRegion {
  FixedRegionKind kind = FixedRegionKind::plane;
  std::string group;                         // group: the gmsh physical surface's name
  Vec3 point{0, 0, 0}, normal{0, 0, 1};      // plane: |n . (X - point)| <= tolerance, n a unit vector
  double tolerance = 1e-9;                   // plane, m
  Vec3 min{0, 0, 0}, max{0, 0, 0};           // box, m (closed)
  Vec3 center{0, 0, 0};                      // sphere, m
  double radius = 0.0;                       // sphere, m (closed)
  std::string field;                         // its JSON pointer ("/fixed/2"), for messages
};

struct BoxSpec {
  Vec3 min{-1.0, -1.0, -2.0};  // m; the default cube of edge 2 m with its top face at z = 0
  Vec3 max{1.0, 1.0, 0.0};
};

struct DistributionSpec {
  DistributionType type = DistributionType::grid;
  int per_edge = 18;          // nodes per box edge (lattice types) when spacing == 0
  double spacing = 0.0;       // m; > 0 chooses the lattice by spacing instead of per_edge
  double jitter = 0.3;        // jittered_grid: displacement bound as a fraction of the spacing
  // graded_grid: the lattice spacing next to the focus, m; the reader's default (absent or 0) is
  // the spacing the scene's sweep and inclusions ask for (required_resolution, core/resolution.h)
  double first_spacing = 0.0;
  bool focus_given = false;      // graded_grid: false = the centre of the top face (the indenter's site)
  Vec3 focus{0.0, 0.0, 0.0};     // graded_grid: the point the lattice is graded toward, m
  uint64_t seed = 1;          // jittered_grid: random seed
  std::filesystem::path node_file;  // node_file: "x y z" per line; holds the absolute path, resolved
                                    // against the scene file's folder
  std::filesystem::path mesh_file;  // mesh: a tetrahedral mesh (.msh gmsh, .node + .ele TetGen), absolute
                                    // path resolved like node_file (JSON key "file"; core/mesh_reader.h)
  // mesh: refined in-process toward the tool (core/mesh_refinement.h, JSON object "refine"):
  // the file is then a coarse base mesh, refined toward `focus` when given, else toward the
  // point of the body's surface nearest the tool, and refocused as the tool moves.
  struct Refinement {
    double size = 0.0;       // the mean tetrahedron edge at the focus, m (7.1); 0 = no refinement. An
                             // object without it: the spacing the scene asks for (core/resolution.h)
    double growth = 1.2;     // G > 1 of (7.1)
    double max_size = 0.0;   // no refinement where (7.1) reaches it, m; 0 = no such limit
    bool enabled() const { return size > 0.0; }
  } refine;
};

struct MlsSpec {
  int neighbors = 16;            // k of the k-nearest-neighbour support (paper: 16)
  int max_neighbors = 0;         // > k: grow a particle's support up to this many neighbours until
                                 // cond(A_i) <= 1e4 (stretched lattices); 0 = k for every particle
  double support_factor = 1.0;   // alpha: h_i = alpha * mean distance to the k neighbours (or the k-th, support_rule)
  SupportRule support_rule = SupportRule::mean_distance;
  IntegrationRule integration = IntegrationRule::nodal;
  VolumeRule volumes = VolumeRule::kernel;
  double hourglass = 0.0;        // dimensionless hourglass-control stiffness (0 = off)
  double regularization = 1e-6;  // relative eigenvalue floor of the moment matrix
  double mass_floor = 0.0;       // beta of (1.18): m_i >= beta * the mean mass of i's neighbours (0 = off)
};

// The hexahedral FEM reference model (model "hex_fem", docs/physics.md §5).
// small strain, corotational ("large"), or the total-Lagrangian neo-Hookean bricks (1.13)
enum class HexFormulation { linear, corotational, neo_hookean };
// Quadrature of the volumetric (lambda) part of K_e: 2x2x2 Gauss points like the
// rest ("full"), or one point at the centre ("reduced": selective reduced
// integration, free of volumetric locking as nu -> 1/2).
enum class HexVolumetricIntegration { full, reduced };
struct HexFemSpec {
  HexFormulation formulation = HexFormulation::linear;  // small strain, or corotational ("large")
  HexVolumetricIntegration volumetric_integration = HexVolumetricIntegration::full;
};

// A region of other material inside the body (scene material.inclusions): a shape and
// its elastic constants. Later inclusions override earlier ones where they overlap; a
// `group` (a mesh's physical volume, applied after the shapes) overrides the shapes.
enum class InclusionShape { sphere, box, group };
struct InclusionSpec {
  InclusionShape shape = InclusionShape::sphere;
  std::string group;           // group: the name of a physical volume group of the mesh
  Vec3 center{0.0, 0.0, 0.0};  // sphere: centre, m
  double radius = 0.0;         // sphere: radius, m
  Vec3 min{0.0, 0.0, 0.0};     // box: lower corner, m
  Vec3 max{0.0, 0.0, 0.0};     // box: upper corner, m
  double young_modulus = 1.0e4;  // Pa
  double poisson_ratio = 0.3;
  double density = 1000.0;       // kg/m^3; the matrix's material.density unless given
  // Whether the point lies in a sphere or box (a group is a set of tetrahedra, not a shape:
  // material_field.h blends it from the mesh).
  bool contains(const Vec3& p) const {
    if (shape == InclusionShape::group) return false;
    if (shape == InclusionShape::sphere) return (p - center).squaredNorm() <= radius * radius;
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
  bool operator==(const InclusionSpec&) const = default;
};

struct MaterialSpec {
  double young_modulus = 1.0e4;   // Pa
  double poisson_ratio = 0.3;
  double density = 1000.0;        // kg/m^3
  double volume_stiffness = 0.0;  // k_v of the volume-restoring term, Pa; 0 = off
  MaterialLaw law = MaterialLaw::stvk;  // MLS: the strain-energy density (mls_forces.h)
  std::vector<InclusionSpec> inclusions;  // heterogeneity (core/material_field.h); empty: homogeneous
};

struct IndenterSpec {
  double radius = 0.5;           // m
  double mass = 1.0;             // kg
  bool position_given = false;   // false: centred over the top face, just touching it
  Vec3 position{0.0, 0.0, 0.0};  // m, initial centre when position_given
  double force = 0.0;            // N, initial commanded force pressing down (-z)
  // The box the tool's centre is kept in, m. A corner not given (infinite) is the body's
  // bounding box's, grown by two radii.
  Vec3 workspace_min = Vec3::Constant(-std::numeric_limits<double>::infinity());
  Vec3 workspace_max = Vec3::Constant(std::numeric_limits<double>::infinity());
  ToolGuide guide = ToolGuide::vertical;
};

// Lengths and speeds that scale with the scene: the reader derives them from the
// indenter radius R where a scene leaves them out or writes 0 (docs/scene-format.md).
constexpr double kContactToleranceOverRadius = 2e-6;    // contact.tolerance = 2e-6 R
constexpr double kRestTravelOverRadius = 1e-5;          // verify.rest: travel over the window <= 1e-5 R
constexpr double kVerifyDepthsOverRadius[2] = {0.02, 0.2};  // verify.forces: Hertz loads for d/R = 0.02 ... 0.2

struct ContactSpec {
  // m, allowed penetration after the contact solve; the reader's default (absent or 0) is
  // kContactToleranceOverRadius x R (1e-6 m for the default R = 0.5 m)
  double tolerance = 1e-6;
  int max_iterations = 200;  // pivoting steps of the active-set solve
};

struct IntegratorSpec {
  IntegratorType type = IntegratorType::rk4;
  double dt = 1e-3;              // s
  double damping = 0.0;          // 1/s, mass-proportional (Rayleigh alpha) damping
  double cg_tolerance = 1e-8;    // implicit Euler: relative residual of the CG solve
  int cg_max_iterations = 1000;  // implicit Euler
  // Threads of the force loops (the caller's and threads - 1 workers, core/thread_pool.h);
  // results are bit-identical between runs for a given count.
  int threads = 1;
  // Symplectic Euler on an MLS model: the longest interval, in ticks, between a particle's
  // elastic updates (subcycling, core/rate_schedule.h), a power of two 1 ... 64; 1 updates
  // every particle every tick. The model's schedule is built for the scene's value.
  int max_interval = 1;
  // Explicit integrators: a dt above the measured stable envelope (time_step.h) is
  // refused unless the scene opts in.
  bool allow_unstable_dt = false;
};

// Per-step health checks (health.h). Zero limits mean "derived from the model".
struct HealthSpec {
  bool enabled = true;
  double energy_factor = 10.0;       // kinetic energy may reach this x (initial energy + work done)
  double max_indenter_speed = 0.0;   // m/s; 0: one minimum particle spacing per step
  double max_penetration = 0.0;      // m; 0: contact tolerance + 5 % of the minimum spacing
  int inversion_sweep_ticks = 64;    // MLS: det F is checked for n / this particles per step
};

// When a quasi-static run (palpate-verify) calls the state "at rest" (docs/physics.md §2).
struct RestSpec {
  // m/s, max mean particle and indenter speed over the window; the reader's default (absent
  // or 0) is kRestTravelOverRadius x R / window (1e-4 m/s for R = 0.5 m, window 0.05 s)
  double velocity_tolerance = 1e-4;
  double force_tolerance = 1e-3;     // relative |contact force - command| / command
  double window = 0.05;              // s the criteria must hold continuously
  double max_time = 60.0;            // s of simulated time before giving up
};

struct VerifySpec {
  // N, the force sweep; the reader's default (absent or empty) is default_verify_forces()
  std::vector<double> forces;
  RestSpec rest;
};

struct Scene {
  std::string name;
  std::string source;        // where the scene came from (file path), for messages
  SolidKind model = SolidKind::mls;  // "mls" (the meshless solid) or "hex_fem" (the FEM reference)
  BoxSpec box;
  // false for a mesh body without /body/box: the mesh may have any shape, its bounding box
  // serves where a box is needed (Model::box_volume is then the mesh's volume). Lattices and
  // node lists always have a box (the default one when absent).
  bool box_given = true;
  DistributionSpec distribution;
  MlsSpec mls;
  HexFemSpec hex_fem;
  MaterialSpec material;
  uint32_t fixed_faces = face_bottom | faces_sides;
  std::vector<FixedRegion> fixed_regions;  // the object elements of `fixed` (the wire's Scene.fixedRegions)
  IndenterSpec indenter;
  ContactSpec contact;
  IntegratorSpec integrator;
  Vec3 gravity{0.0, 0.0, 0.0};  // m/s^2, acts on the body and the indenter
  VerifySpec verify;
  HealthSpec health;
};

// "key=value" overrides applied to the JSON before validation; key is the dotted
// path of a field ("body.distribution.per_edge"), value a JSON literal or a bare string.
using SceneOverrides = std::vector<std::pair<std::string, std::string>>;

// Whether the node or mesh file a scene names must exist when it is read: `not_required`
// reads the description of a scene whose mesh is still to be made (palpate-resolution);
// build_model still needs the file.
enum class SceneFiles { required, not_required };

// Reads and validates a scene file. Throws SceneError naming file, field and reason.
Scene load_scene(const std::filesystem::path& file, const SceneOverrides& overrides = {},
                 SceneFiles files = SceneFiles::required);
// The same from text; base_dir resolves relative file names inside the scene.
Scene parse_scene(const std::string& json_text, const std::string& source_name,
                  const std::filesystem::path& base_dir, const SceneOverrides& overrides = {},
                  SceneFiles files = SceneFiles::required);

// The default force sweep: the Hertz loads (docs/physics.md (3.2)) of the depths
// d = R x (0.02, 0.04, ..., 0.2) with the scene's material and radius (for the default
// R = 0.5 m: d = 0.01 ... 0.1 m, the paper's sweep).
std::vector<double> default_verify_forces(const MaterialSpec& material, double radius);

// The JSON pointer of every field a scene file may set ("/body/distribution/per_edge"),
// in the order the reader checks them (the order of docs/scene-format.md).
std::vector<std::string> scene_field_paths();

// The scene-file names of enumerated values ("symplectic_euler").
const char* to_string(SolidKind);
const char* to_string(IntegratorType);
const char* to_string(ToolGuide);
const char* to_string(MaterialLaw);
const char* to_string(HexFormulation);
const char* to_string(HexVolumetricIntegration);
const char* to_string(DistributionType);
const char* to_string(SupportRule);
const char* to_string(IntegrationRule);
const char* to_string(VolumeRule);

}  // namespace palpate
