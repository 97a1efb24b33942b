// What a Frame on the wire holds, filled from a published Snapshot (server/frames.h).
#include "server/frames.h"

#include <algorithm>

#include "core/stress.h"

namespace palpate::server {

namespace {

void fill_local_model(wire::LocalModel::Builder b, const LocalModel& m) {
  set_vec3(b.initOrigin(), m.origin);
  set_vec3(b.initForce(), m.force);
  auto k = b.initStiffness(9);
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) k.set(3 * i + j, m.stiffness(i, j));
  b.setValidRadius(m.valid_radius);
  b.setStiffnessTick(m.stiffness_tick);
}

// A per-particle list of `components` floats per particle, all particles or (surface_only) the
// surface vertices in their order.
template <class List>
void fill_particle_list(List list, const float* values, int components, const std::vector<uint32_t>* vertices) {
  if (vertices == nullptr) {
    for (unsigned k = 0; k < list.size(); ++k) list.set(k, values[k]);
    return;
  }
  unsigned k = 0;
  for (const uint32_t i : *vertices)
    for (int c = 0; c < components; ++c) list.set(k++, values[static_cast<size_t>(components) * i + c]);
}

}  // namespace

void set_vec3(wire::Vec3::Builder b, const Vec3& v) {
  b.setX(v[0]);
  b.setY(v[1]);
  b.setZ(v[2]);
}

const DerivedFields* derived_fields(const Model& m, const Snapshot& s, const FieldRequest& want, DerivedFields& d) {
  if (!want.derived() || !s.has_body_position) return nullptr;
  if (d.publish_ns != s.publish_ns || d.tick != s.tick) {
    d.publish_ns = s.publish_ns;
    d.tick = s.tick;
    d.has_displacement = d.has_von_mises = false;
  }
  const int n = m.particle_count;
  if (want.displacement && !d.has_displacement) {
    d.displacement.resize(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i)
      d.displacement[i] = static_cast<float>((s.body_position.col(i) - m.rest_position.col(i)).norm());
    d.has_displacement = true;
  }
  if (want.von_mises && !d.has_von_mises) {
    von_mises_stress(m, s.body_position, d.scratch);
    d.von_mises.assign(d.scratch.begin(), d.scratch.end());
    d.has_von_mises = true;
  }
  return &d;
}

FieldRequest request_of(wire::FrameFields::Reader f) {
  return {f.getPositions(), f.getContacts(), f.getDisplacementMagnitude(), f.getVonMises(), f.getSurfaceOnly()};
}

void fill_frame(wire::Frame::Builder f, const Snapshot& s, const FieldRequest& want, const DerivedFields* derived,
                const std::vector<uint32_t>& surface_vertices, const HapticSample* render) {
  f.setTick(s.tick);
  f.setSimTime(s.sim_time);
  f.setPublishNs(render ? render->publish_ns : s.publish_ns);
  f.setHapticTick(render ? render->haptic_tick : -1);
  f.setModelAgeNs(render ? render->publish_ns - render->model_publish_ns : 0);
  f.setDeadlineMisses(s.deadline_misses);
  f.setHapticMisses(render ? render->haptic_misses : 0);
  set_vec3(f.initIndenterPosition(), s.tool_position);
  f.setIndenterVelocity(s.tool_velocity[2]);
  f.setIndenterContactForce(s.tool_contact_force[2]);
  f.setIndentation(s.indentation);
  f.setForceCommand(-s.force_command[2]);
  // Multirate: the newest command the rendered force includes (docs/protocol.md, "Multirate"),
  // not the newest step's: a render made from an older step than `s` (the step that switched
  // to position mode not yet rendered) would otherwise claim a setPosition it does not render.
  f.setCommandSeq(render ? render->command_seq : s.command_seq);
  f.setRecoveries(s.recoveries);
  set_vec3(f.initToolVelocity(), s.tool_velocity);
  set_vec3(f.initToolContactForce(), s.tool_contact_force);
  set_vec3(f.initForceVector(), s.force_command);
  f.setMode(s.position_mode ? wire::ControlMode::POSITION : wire::ControlMode::FORCE);
  set_vec3(f.initTarget(), render ? render->target : s.target);
  set_vec3(f.initRenderForce(), render ? render->render_force : s.render_force);
  f.setForceSaturated(render ? render->force_saturated : s.force_saturated);
  fill_local_model(f.initContactModel(), s.contact_model);
  fill_local_model(f.initRenderModel(), s.render_model);
  const std::vector<uint32_t>* vertices = want.surface_only ? &surface_vertices : nullptr;
  auto particles = [&](size_t all) { return static_cast<unsigned>(vertices ? vertices->size() : all); };
  if (want.positions && s.has_positions)
    fill_particle_list(f.initPositions(3 * particles(s.positions.size() / 3)), s.positions.data(), 3, vertices);
  if (derived != nullptr && want.displacement)
    fill_particle_list(f.initDisplacementMagnitude(particles(derived->displacement.size())),
                       derived->displacement.data(), 1, vertices);
  if (derived != nullptr && want.von_mises)
    fill_particle_list(f.initVonMises(particles(derived->von_mises.size())), derived->von_mises.data(), 1, vertices);
  if (want.contacts && s.has_contacts) {
    auto nodes = f.initContactNodes(static_cast<unsigned>(s.contact_nodes.size()));
    for (unsigned k = 0; k < s.contact_nodes.size(); ++k) nodes.set(k, s.contact_nodes[k]);
    auto forces = f.initContactForces(static_cast<unsigned>(s.contact_forces.size()));
    for (unsigned k = 0; k < s.contact_forces.size(); ++k) forces.set(k, s.contact_forces[k]);
  }
}

capnp::MessageSize frame_size_hint(const Snapshot& s, const FieldRequest& want, size_t surface_vertices) {
  uint64_t words = 160;
  const size_t n = want.surface_only ? surface_vertices : s.positions.size() / 3;
  if (want.positions && s.has_positions) words += 3 * n / 2 + 2;
  if (want.displacement) words += n / 2 + 2;
  if (want.von_mises) words += n / 2 + 2;
  if (want.contacts && s.has_contacts) words += s.contact_nodes.size() + 4;
  return {words, 0};
}

void fill_percentiles(wire::Percentiles::Builder b, const Histogram::Summary& s) {
  b.setP50(s.p50);
  b.setP99(s.p99);
  b.setMax(s.max);
}

}  // namespace palpate::server
