#pragma once
// The stress of the elastic solid per particle (MLS) or node (hex FEM), for display:
// Frame.vonMises on the wire (docs/protocol.md) and the ParaView export (core/vtk_writer.h).
// Nothing here runs in the step; the server computes it off the simulation thread.
//
// MLS (docs/physics.md §1): the deformation gradient F_i of, the first Piola stress
// P_i of the scene's law with the particle's own Lame parameters ((1.4) St Venant-Kirchhoff,
// (1.6) corotational, (1.8) linear, (1.14) neo-Hookean, (1.16) for inclusions) plus the volume
// term, then the Cauchy stress
//
//     sigma_i = J^-1 P_i F_i^T,   J = det F_i                         (Cauchy from first Piola)
//
// For the small-strain linear law (1.8) the stress is P itself (symmetric; the law has no
// current configuration to push forward to). The volume term adds k_v (J - 1) I to sigma:
// a pressure, which leaves the von Mises stress unchanged.
//
// Hex FEM (docs/physics.md §5): each element's stress at its centre, averaged over the
// elements around a node weighted by their volumes. Linear bricks: sigma = lambda tr(eps) I +
// 2 mu eps with eps = sym(grad u) (the continuum of (5.1)); corotational: the same in the
// element's rotated frame (u' = R_e^T x - X), rotated back, R_e sigma' R_e^T; neo-Hookean:
// J^-1 P F^T with P from (1.14) and F the trilinear map's gradient at the centre.
//
// The von Mises equivalent stress of a (symmetric part of a) stress tensor:
//
//     sigma_vM = sqrt( 1/2 [(s11 - s22)^2 + (s22 - s33)^2 + (s33 - s11)^2]
//                      + 3 (s12^2 + s23^2 + s31^2) )                   (= sqrt(3/2 s':s'), s' the deviator)
//
// zero for any pressure, |s11| for uniaxial stress. Pa throughout.
#include <vector>

#include "core/model.h"
#include "core/types.h"

namespace palpate {

// sigma_vM of the symmetric part of sigma, Pa.
double von_mises(const Mat3& sigma);

// The Cauchy stress of MLS particle `particle` (its own Lame parameters, the model's law and
// volume stiffness k_v) at deformation gradient F (above).
Mat3 mls_cauchy_stress(const Model& model, const Mat3& F, int particle);

// sigma (resized to n, overwritten) = the stress of every particle (MLS) or node (hex FEM)
// at positions x (3 x n), Pa. Allocates; not for a real-time step.
void cauchy_stress(const Model& model, const Points& x, std::vector<Mat3>& sigma);

// von_mises of cauchy_stress for every particle or node (out resized to n), Pa.
void von_mises_stress(const Model& model, const Points& x, std::vector<double>& out);

}  // namespace palpate
