#pragma once
// A converged reference for a body of any shape (docs/physics.md §5, "A reference for any
// shape"): the scene's body as linear elastic four-node tetrahedra (constant strain) on a
// family of tetrahedral meshes refined toward the site, each pressed by the frictionless
// sphere through the exact linearised static solve (static_contact.h, LinearBody), and
// Richardson extrapolation of the indentation at each force over the family's element sizes
// at the site, as finite_cube_reference does over its lattices. It shares nothing with the
// MLS model but the mesh reader, the fixed-region selection and the surface's first-touch
// height: another discretisation (finite elements, not collocation), another solve (static,
// not a dynamic settle), so it is an independent truth for the MLS scenes of curved bodies,
// where the hex reference, which builds box lattices, has none.
#include <array>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/SparseCore>

#include "analysis/static_contact.h"
#include "core/reference_file.h"
#include "core/scene.h"
#include "core/types.h"

namespace palpate {

// The lower triangle (row >= column) of the stiffness of linear elastic constant-strain
// tetrahedra over the 3n DOFs (3 i + c), one 12 x 12 block per tetrahedron (5.9):
// K_t = V_t B_t^T D_t B_t, B_t the strain of the linear shape functions' gradients, D_t the
// isotropic elasticity of the tetrahedron's Lame parameters. Duplicates are left to be summed.
void tetrahedra_stiffness(const Points& X, const std::vector<std::array<int, 4>>& tetrahedra,
                          const std::vector<double>& lambda, const std::vector<double>& mu,
                          std::vector<Eigen::Triplet<double>>& lower);

// The scene's body on the tetrahedral mesh `file` (the scene's own when empty) as a LinearBody:
// fixed as the scene says (box faces of the mesh's bounding box, mesh groups, planes, boxes,
// spheres), each tetrahedron of the matrix's material or of the last inclusion that contains its
// centroid (a group inclusion: its tetrahedra), the candidates the free boundary nodes within
// the sphere's radius of the site, and the touch height the exact first contact of the sphere
// with the mesh's boundary faces over the site (surface.h). Throws SceneError / runtime_error
// naming the file for a mesh or a scene it cannot use.
LinearBody tet_body(const Scene& scene, const std::filesystem::path& file = {});

// One mesh of the family: the file and its element size at the site, m (h of the extrapolation).
struct TetMeshLevel {
  std::filesystem::path file;
  double spacing = 0.0;
};

// The reference at `forces` on `levels` (at least 3, coarse to fine: spacing decreasing). Each
// level's indentation is stored with its node count, its spacing as first_spacing (per_edge 0);
// Richardson in h = spacing as finite_cube_reference's. The key is reference_key(scene): a
// reference of the same problem as the hex one would be, found by palpate-verify the same way.
Reference tet_mesh_reference(const Scene& scene, const std::vector<double>& forces,
                             const std::vector<TetMeshLevel>& levels,
                             const std::function<void(const std::string&)>& progress = {});

}  // namespace palpate
