#pragma once
// Fixed-particle boundary conditions selected by region (faces of the cloud's
// bounding box). Fixed particles are projected: zero inverse mass, so their
// force and velocity never act (as SOFA's FixedConstraint).
#include <cstdint>
#include <string>
#include <vector>

#include "core/node_cloud.h"
#include "core/scene.h"
#include "core/types.h"

namespace palpate {

// 1 for every particle lying on one of the faces in `faces` (bits of palpate::Face),
// within tolerance * the bounding-box diagonal of the face plane.
std::vector<uint8_t> particles_on_faces(const Points& positions, uint32_t faces, double tolerance = 1e-9);

// Sets fixed[i] = 1 for every particle of `cloud` in `region` (scene.h FixedRegion): a mesh's
// physical surface group (its nodes), within the plane's tolerance, inside the closed box or
// sphere. Throws SceneError at region.field for a group on a body that is not a mesh, a name
// the mesh does not have (listing those it has), or a region that selects no particle.
void fix_region(const NodeCloud& cloud, const FixedRegion& region, const std::string& source,
                std::vector<uint8_t>& fixed);

// The particles the scene fixes: those on its fixed box faces (of the cloud's bounding box),
// then those of each fixed region (fix_region), 1 for fixed. Throws as fix_region.
std::vector<uint8_t> fixed_particles(const Scene& scene, const NodeCloud& cloud);

}  // namespace palpate
