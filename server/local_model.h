#pragma once
// The local models a frame carries for a haptic servo loop faster than the tick
// rate (docs/protocol.md, "The local contact model"): the force on a point near
// an origin, linearised, F(x) = F0 + K (x - x0), valid within a radius.
#include "core/options.h"
#include "core/types.h"
#include "server/snapshot.h"

namespace palpate::server {

// renderForce (Frame.renderForce) as a function of the device position, from the
// contact model of the tool. Position mode, with the tool quasi-static over a servo
// period (its inertia and the coupling's damping neglected): the tool sits where the
// coupling balances the contact, k (x_d - c) + F_c(c) = 0, so a device displacement
// dx_d moves it by dc = (k I - K_c)^-1 k dx_d and the rendered force -k (x_d - c)
// changes by
//     dF_render = k (k I - K_c)^-1 K_c dx_d,                (docs/protocol.md (P.1))
// the coupling and the contact in series; the tool moves no further than the device
// (K_c is negative semi-definite), so the contact model's radius serves. Force mode:
// the contact model itself, about the tool's centre.
LocalModel render_model(const LocalModel& contact, bool position_mode, const Vec3& target,
                        const Vec3& render_force, const CouplingOptions& coupling);

}  // namespace palpate::server
