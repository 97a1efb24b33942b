#pragma once
// The boundary surface of the undeformed body (Model::surface_triangles) and the
// indenter's first contact with it.
//
//   mesh clouds      the mesh's boundary faces (triangles of one tetrahedron, mesh_reader.h);
//   lattice clouds   (grid, jittered_grid, graded_grid and the hex FEM's lattice) the six box
//                    faces triangulated over the lattice nodes, two triangles per face cell;
//   node_file clouds none (no connectivity is known).
// Every triangle (a, b, c) is counterclockwise seen from outside: (X_b - X_a) x (X_c - X_a)
// points out of the body.
#include <Eigen/Core>

#include "core/node_cloud.h"
#include "core/types.h"

namespace palpate {

using SurfaceTriangles = Eigen::Matrix<int, 3, Eigen::Dynamic>;  // 3 x T particle indices

// The box faces of a lattice of `per_axis` nodes (index a + nx (b + ny c), the order of
// grid_nodes), two triangles per face cell: 4 (nx-1)(ny-1) + 4 (ny-1)(nz-1) + 4 (nz-1)(nx-1).
SurfaceTriangles lattice_surface(const Eigen::Vector3i& per_axis);

// The surface of a cloud (see above): empty for node lists.
SurfaceTriangles cloud_surface(const NodeCloud& cloud);

// Height of the centre of a sphere of `radius`, coming down along -z over (cx, cy), when it
// first touches one of the triangles (docs/physics.md (2.16)): the largest z with
// dist((cx, cy, z), T) = radius over the triangles T, found exactly from the three kinds of
// closest feature (face interior, edge, vertex). -infinity when the sphere passes by all.
double sphere_first_contact_height(const Points& X, const SurfaceTriangles& triangles, double cx, double cy,
                                   double radius);

}  // namespace palpate
