#pragma once
// A stored reference of the finite block (scenes/references/*.json, written by
// palpate-reference --out; the computation is analysis/reference.h): what it is a
// reference of (its key), and the converged indentation at each force. Read by
// palpate-verify and by the server, which gives a session's viewers the reference
// curve of their scene (SessionInfo.reference).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/scene.h"

namespace palpate {

// The site of an indentation (docs/physics.md §4, "Off-centre sites"): the point (x, y)
// of the top face over which the tool presses. It is the scene's indenter.position
// (x, y), or the centre of the top face when the scene gives none; palpate-verify and
// palpate-reference --site X,Y set that same field (place_indenter_at_site), so the
// model's start, the touch height, the static solve's candidates, the reference's
// lattice focus and its key all follow one value.

// The site of a scene: indenter.position's (x, y), else the centre of the box's top face.
Eigen::Vector2d indenter_site(const Scene& scene);

// The centre (x, y) of the box's top face, and whether `site` is it (to 1e-9 of the face's edge).
Eigen::Vector2d top_face_centre(const Scene& scene);
bool at_top_face_centre(const Scene& scene, const Eigen::Vector2d& site);

// One level of the graded family (finite_cube_reference, analysis/reference.h).
struct ReferenceLevel {
  int per_edge = 0;
  int nodes = 0;
  double first_spacing = 0.0;      // m
  std::vector<double> indentation; // per force, m
  std::vector<double> forces;      // the large-strain reference: the force at each depth, N (else empty)
  double seconds = 0.0;            // wall time of the level (assembly, factorisation, sweep)
};

struct Reference {
  std::vector<double> forces;        // N
  std::vector<ReferenceLevel> levels;
  std::vector<double> indentation;   // d*(F), extrapolated, m
  std::vector<double> uncertainty;   // m
  std::vector<double> order;         // observed convergence order p per force
  std::string key;                   // what the reference depends on (reference_key)
};

// The scene fields the reference depends on, as one line (box, material, fixed faces,
// indenter radius and site); two scenes with the same key share a reference. The body is
// "box=[min][max]", or for a mesh body without a box (any shape) "mesh=" mesh_key. The site
// is "centre" for the centre of the top face (given or not), else "[x,y]".
std::string reference_key(const Scene& scene);

// A mesh file as a reference key names it: its file name and the FNV-1a 64 hash of its bytes
// (TetGen: the .node's then the .ele's), "palpation_dome.msh#0123456789abcdef"; "#unread" when
// the file cannot be read. The same file in another folder (the guide's scene) has the same key.
std::string mesh_key(const std::filesystem::path& mesh_file);

// The key of the large-strain reference of the scene's block (analysis/reference.h,
// large_strain_reference): reference_key + the law and the held tool.
std::string large_strain_reference_key(const Scene& scene);

// d*(F) at an arbitrary force in the reference's range: d^(3/2) interpolated linearly
// in F (Hertz: F ~ d^(3/2)), exact at the reference forces. NaN outside the range.
double reference_indentation(const Reference& reference, double force);

// A reference file written by palpate-reference --out (throws std::runtime_error).
Reference load_reference(const std::filesystem::path& file);

// The stored reference in `folder` (*.json written by palpate-reference --out) whose
// key matches the scene's; nullopt when there is none.
std::optional<Reference> find_reference(const Scene& scene, const std::filesystem::path& folder);

// A reference from its JSON text (throws std::runtime_error naming the problem).
Reference reference_from_json(const std::string& text);

}  // namespace palpate
