#pragma once
// Fixed-particle boundary conditions selected by region (faces of the cloud's
// bounding box). Fixed particles are projected: zero inverse mass, so their
// force and velocity never act (as SOFA's FixedConstraint).
#include <cstdint>
#include <vector>

#include "core/types.h"

namespace palpate {

// 1 for every particle lying on one of the faces in `faces` (bits of palpate::Face),
// within tolerance * the bounding-box diagonal of the face plane.
std::vector<uint8_t> particles_on_faces(const Points& positions, uint32_t faces, double tolerance = 1e-9);

}  // namespace palpate
