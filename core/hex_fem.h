#pragma once
// Hexahedral finite elements (docs/physics.md §5): 8-node trilinear bricks on the
// lattice of the scene's box, 2x2x2 Gauss integration, isotropic linear
// elasticity, in a linear small-strain and a corotational variant (the
// "large" method of SOFA's HexahedronFEMForceField: the element rotation is
// taken from its deformed edges, forces f_e = -R_e K_e (R_e^T x_e - X_e)), and the
// total-Lagrangian neo-Hookean bricks of core/hex_neo_hookean.h.
// Lumped masses are the lattice volumes times the density.
#include <array>
#include <vector>

#include <Eigen/Core>

#include "core/scene.h"
#include "core/types.h"

namespace palpate {

using ElementMatrix = Eigen::Matrix<double, 24, 24>;  // dofs: node a, component c -> 3 a + c
// dN_a/dx (column a, local node order below) of the trilinear shape functions of an
// hx x hy x hz brick at natural coordinates xi in [-1, 1]^3.
using BrickGradients = Eigen::Matrix<double, 3, 8>;
BrickGradients brick_shape_gradients(const Eigen::Vector3d& size, const double xi[3]);

// The mesh and everything precomputed from it (part of the Model for "hex_fem").
struct HexMesh {
  HexFormulation formulation = HexFormulation::linear;
  int element_count = 0;
  // Local node order: (0,0,0) (1,0,0) (1,1,0) (0,1,0) (0,0,1) (1,0,1) (1,1,1) (0,1,1)
  // in the (x, y, z) lattice directions.
  std::vector<std::array<int, 8>> element_nodes;  // element_count
  std::vector<int> element_type;                  // element_count: index into the arrays below
  std::vector<ElementMatrix> element_stiffness;   // K_e per distinct (element size, lambda, mu) (A regular
                                                  // homogeneous grid has one.)
  std::vector<Eigen::Vector3d> element_size;      // edge lengths (hx, hy, hz) per type
  std::vector<double> element_lambda, element_mu; // Lame parameters per type, Pa
  // Per element type, for the neo-Hookean formulation (core/hex_neo_hookean.h): the shape
  // gradients at the 2x2x2 Gauss points (+-1/sqrt 3)^3 in kCorner order and the Gauss weight
  // hx hy hz / 8.
  std::vector<std::array<BrickGradients, 8>> gauss_gradients;
  std::vector<double> gauss_weight;
};


// K_e of an hx x hy x hz brick, Lame parameters lambda, mu: 2x2x2 Gauss points, or
// (volumetric = reduced) the lambda part at the centre only (selective reduced integration).
ElementMatrix hex_element_stiffness(const Eigen::Vector3d& size, double lambda, double mu,
                                    HexVolumetricIntegration volumetric = HexVolumetricIntegration::full);

// The mesh of a lattice with `per_axis` nodes per axis, node i = a + nx (b + ny c),
// coordinates taken from `rest_position` (which may be graded along each axis). With
// `heterogeneous` (a material with inclusions), each element's lambda, mu are its brick's
// blend (material_field.h, (1.16)) instead of the given ones, the matrix's.
HexMesh hex_mesh(const Points& rest_position, const Eigen::Vector3i& per_axis, double lambda, double mu,
                 HexFormulation formulation,
                 HexVolumetricIntegration volumetric = HexVolumetricIntegration::full,
                 const MaterialSpec* heterogeneous = nullptr);

// Rotation of an element from its current node positions (columns of F at the
// centre, Gram-Schmidt on the x and y directions as SOFA's "large" method).
Mat3 hex_element_rotation(const Points& x, const std::array<int, 8>& nodes, const Eigen::Vector3d& size);

// f (3 x n, overwritten) = internal nodal forces at positions x.
void hex_internal_forces(const HexMesh& mesh, const Points& rest, const Points& x, Points& f);
// Strain energy 1/2 u'^T K u' summed over elements (u' the element displacement in
// its rotated frame; u' = x - X for the linear formulation), J.
double hex_strain_energy(const HexMesh& mesh, const Points& rest, const Points& x);
// Tangent stiffness, matrix-free: rotations (9 per element) cached at x, then
// df = -R K R^T dx per element (exact for linear; SOFA's approximation for corotational);
// neo-Hookean: F and F^-T at the Gauss points cached, the exact tangent (5.6).
void hex_linearize(const HexMesh& mesh, const Points& x, std::vector<double>& cached_rotation);
void hex_force_differential(const HexMesh& mesh, const std::vector<double>& cached_rotation, const Points& dx,
                            Points& df);

}  // namespace palpate
