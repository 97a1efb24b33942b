#pragma once
// What a Frame on the wire holds, filled from a published Snapshot on the RPC thread
// (docs/protocol.md, Frame): the fields a subscriber or a step() call asked for, the
// per-particle fields derived from the double-precision positions (computed once per
// frame, whichever subscribers send it), and the size hint of the message.
#include <cstdint>
#include <vector>

#include <capnp/message.h>

#include "core/model.h"
#include "protocol/palpate.capnp.h"
#include "server/haptic_loop.h"
#include "server/histogram.h"
#include "server/snapshot.h"

namespace palpate::server {

void set_vec3(wire::Vec3::Builder b, const Vec3& v);
void fill_percentiles(wire::Percentiles::Builder b, const Histogram::Summary& s);

// Fields computed from a published frame's double-precision positions (Snapshot::body_position)
// on the RPC thread, off the simulation thread: once per frame, whichever subscribers send it.
struct DerivedFields {
  int64_t publish_ns = -1, tick = -1;  // the frame they belong to
  bool has_displacement = false, has_von_mises = false;
  std::vector<float> displacement;  // n, |x - X|, m
  std::vector<float> von_mises;     // n, Pa (core/stress.h)
  std::vector<double> scratch;
};

// What one subscriber (or step() call) asked for (wire FrameFields).
struct FieldRequest {
  bool positions = false, contacts = false, displacement = false, von_mises = false, surface_only = false;
  bool derived() const { return displacement || von_mises; }
};

FieldRequest request_of(wire::FrameFields::Reader f);

// The frame's derived fields that `want` asks for, computed into `d` now unless they already
// were for this frame; null when it asks for none or the frame has no double-precision
// positions yet (a subscriber newer than the frame).
const DerivedFields* derived_fields(const Model& m, const Snapshot& s, const FieldRequest& want, DerivedFields& d);

// `render`: multirate, the render tick the frame is for (its force, target and time on
// the step's body); null: the step's own frame.
void fill_frame(wire::Frame::Builder f, const Snapshot& s, const FieldRequest& want, const DerivedFields* derived,
                const std::vector<uint32_t>& surface_vertices, const HapticSample* render = nullptr);

capnp::MessageSize frame_size_hint(const Snapshot& s, const FieldRequest& want, size_t surface_vertices);

}  // namespace palpate::server
