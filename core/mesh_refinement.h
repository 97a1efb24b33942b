#pragma once
// Local refinement of a tetrahedral mesh toward a focus: the resolution that follows the
// tool (docs/physics.md §7). A coarse base mesh of the body is refined in-process, in
// milliseconds, wherever its tetrahedra are longer than the size the focus asks for there:
//
//   h(X) = focus_size + (growth - 1) |X - focus|                               (7.1)
//
// a tetrahedron whose mean edge exceeds h at its centroid is bisected (the mean edge, as
// gmsh's size fields mean it: a focus_size of 1 mm gives edges of about 1 mm there), unless h
// there has reached max_size (then the base's own grading is kept: the refinement stays
// within (max_size - focus_size) / (growth - 1) of the focus). Bisection is
// Rivara's longest-edge propagation path (LEPP): a tetrahedron is always cut through the
// midpoint of its longest edge, and every tetrahedron around that edge is cut with it, after
// those whose own longest edge is another have been cut first (recursively). The result is
// conforming (no hanging nodes), its shapes stay within a bounded factor of the base's, and
// it depends only on the base mesh and the focus (ties between equal edges broken by the
// vertices' indices), never on the order of earlier refinements: refocusing always starts
// from the base.
//
// Each new vertex is an edge midpoint, except on a boundary edge inside a smooth curved
// surface, where it is the middle of the Hermite curve the surface's normals at the edge's
// ends define (7.1a), so that a curved body's new surface vertices lie on the curved surface
// rather than on the base's facets. It is on the boundary when its edge is, and in a
// physical surface group when both ends are and a boundary triangle of the group contains
// the edge. Children keep their parent's region tag. Nodal volumes, boundary faces and the
// total volume are recomputed as the reader computes them (mesh_reader.h); on a body of flat
// faces bisection keeps the total volume exactly (up to round-off).
#include <cmath>

#include "core/mesh_reader.h"
#include "core/types.h"

namespace palpate {

struct MeshRefinement {
  Vec3 focus{0, 0, 0};     // the point the mesh is refined toward (a point of the body's surface), m
  double focus_size = 0;   // h at the focus: the mean edge allowed there, m (> 0)
  double growth = 1.2;     // G > 1: the allowed edge grows by (G - 1) per metre from the focus
  double max_size = INFINITY;  // where (7.1) reaches it, nothing is refined (the base's own size), m
};

// The allowed mean edge at distance r from the focus, (7.1).
inline double refinement_size(const MeshRefinement& spec, double r) {
  return spec.focus_size + (spec.growth - 1.0) * r;
}

// `base` refined toward spec.focus. The base's vertices keep their indices (0 ... n-1); the
// midpoints follow. Throws std::invalid_argument when focus_size <= 0, growth <= 1, or the
// refinement would pass kMaxMeshNodes.
TetMesh refine_mesh(const TetMesh& base, const MeshRefinement& spec);

// The point of the mesh's boundary surface nearest to p (p itself when the surface is empty).
Vec3 nearest_boundary_point(const TetMesh& mesh, const Vec3& p);

}  // namespace palpate
