#pragma once
// The neo-Hookean hex FEM (hex_fem.formulation "neo_hookean", docs/physics.md §5,
// (5.4)-(5.6)): total-Lagrangian trilinear bricks, 2x2x2 Gauss points, the compressible
// neo-Hookean law (1.13)-(1.15) at each. The finite-strain reference for the MLS solid with
// material.law "neo_hookean". Called by hex_fem.cpp's dispatch; the per-type Gauss data
// (HexMesh::gauss_gradients) is set up by hex_mesh.
#include <vector>

#include "core/hex_fem.h"
#include "core/types.h"

namespace palpate {

// f += the element forces at positions x (5.5); f is not cleared.
void hex_neo_hookean_add_forces(const HexMesh& mesh, const Points& x, Points& f);
// Strain energy sum_e sum_g w_g psi(F_g) (5.4), J; +infinity when a Gauss point is inverted.
double hex_neo_hookean_energy(const HexMesh& mesh, const Points& x);
// F and F^-T at every Gauss point of every element (18 doubles x 8 per element) into cache.
void hex_neo_hookean_linearize(const HexMesh& mesh, const Points& x, std::vector<double>& cache);
// df (overwritten) = -K(x) dx, the exact tangent (5.6) at the cached x.
void hex_neo_hookean_force_differential(const HexMesh& mesh, const std::vector<double>& cache, const Points& dx,
                                        Points& df);

}  // namespace palpate
