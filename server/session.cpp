// Sessions, subscriptions and streaming (the RPC thread).
//
// Streaming policy (docs/protocol.md, "Flow control"): per subscriber {inFlight, nextDue, interval}.
// When the simulation publishes (eventfd wake-up), the newest frame goes to every
// subscriber that is due and has nothing in flight; a due subscriber that still
// has a frame in flight skips this one (drop-newest) and it is counted. Nothing
// queues: the triple buffer holds only the newest frame, so a slow viewer costs
// the loop and the other subscribers nothing.
#include "server/session.h"

#include <algorithm>
#include <thread>
#include <cmath>
#include <stdexcept>

#include <capnp/message.h>
#include <kj/debug.h>
#include <spdlog/spdlog.h>

#include "core/stress.h"

namespace palpate::server {

namespace {

void set_vec3(wire::Vec3::Builder b, const Vec3& v) {
  b.setX(v[0]);
  b.setY(v[1]);
  b.setZ(v[2]);
}

void fill_local_model(wire::LocalModel::Builder b, const LocalModel& m) {
  set_vec3(b.initOrigin(), m.origin);
  set_vec3(b.initForce(), m.force);
  auto k = b.initStiffness(9);
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) k.set(3 * i + j, m.stiffness(i, j));
  b.setValidRadius(m.valid_radius);
  b.setStiffnessTick(m.stiffness_tick);
}

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

FieldRequest request_of(wire::FrameFields::Reader f) {
  return {f.getPositions(), f.getContacts(), f.getDisplacementMagnitude(), f.getVonMises(), f.getSurfaceOnly()};
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

// `render`: multirate, the render tick the frame is for (its force, target and time on
// the step's body); null: the step's own frame.
void fill_frame(wire::Frame::Builder f, const Snapshot& s, const FieldRequest& want, const DerivedFields* derived,
                const std::vector<uint32_t>& surface_vertices, const HapticSample* render = nullptr) {
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
  f.setCommandSeq(render ? std::max(render->command_seq, s.command_seq) : s.command_seq);
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

}  // namespace

// ---------------------------------------------------------------------------
// ServerContext

namespace {
kj::Promise<void> beat(kj::Timer& timer, RpcHeartbeat& heartbeat) {
  heartbeat.last_ns.store(now_ns(), std::memory_order_relaxed);
  return timer.afterDelay(RpcHeartbeat::kPeriodNs * kj::NANOSECONDS).then([&timer, &heartbeat]() {
    return beat(timer, heartbeat);
  });
}
}  // namespace

ServerContext::ServerContext(kj::AsyncIoContext& io_, ServerOptions options_)
    : io(io_), options(std::move(options_)) {
  tasks_.add(beat(io.provider->getTimer(), heartbeat));
}

void ServerContext::ErrorHandler::taskFailed(kj::Exception&& e) {
  spdlog::debug("task ended: {}", e.getDescription().cStr());
}

// A cancelled session still starting, held by its task in tasks_ until the thread ends.
struct ServerContext::Closing {
  Closing(ServerContext& c, std::unique_ptr<Simulation> s) : ctx(c), sim(std::move(s)) {
    wake = ctx.io.lowLevelProvider->wrapInputFd(
        sim->wake_fd(), kj::LowLevelAsyncIoProvider::ALREADY_CLOEXEC | kj::LowLevelAsyncIoProvider::ALREADY_NONBLOCK);
    ctx.closing_.insert(this);  // last: the destructor runs only for a complete object
  }
  ~Closing() noexcept(false) {
    wake = nullptr;  // before the Simulation closes the eventfd
    ctx.closing_.erase(this);
    sim->stop();     // the thread has ended its start (or does so now): a short join
  }
  ServerContext& ctx;
  std::unique_ptr<Simulation> sim;
  kj::Own<kj::AsyncInputStream> wake;
  uint8_t buffer[8] = {};
};

// Resolves once the thread left Phase::starting (it writes the eventfd after setting
// the phase, so the phase is checked before each wait).
kj::Promise<void> ServerContext::wait_until_started(Closing& closing) {
  if (closing.sim->phase() != Phase::starting) return kj::READY_NOW;
  return closing.wake->tryRead(closing.buffer, 1, sizeof closing.buffer).then([&closing](size_t) {
    return wait_until_started(closing);
  });
}

void ServerContext::adopt_starting(std::unique_ptr<Simulation> sim) {
  sim->cancel();
  auto closing = kj::heap<Closing>(*this, std::move(sim));
  Closing& ref = *closing;
  tasks_.add(wait_until_started(ref).attach(kj::mv(closing)));
}

// ---------------------------------------------------------------------------
// SessionImpl

// How read-only views and subscriptions reach their session without keeping it alive: the
// session clears `session` when it ends. RPC thread only.
struct SessionLink {
  SessionImpl* session;
};

class SessionImpl final : public wire::Session::Server {
 public:
  // Starts the session's thread on the plan; the scene is resolved and validated there.
  // `opener`: the connection that opened it (its count of live sessions).
  SessionImpl(ServerContext& ctx, OpenPlan plan, std::shared_ptr<ConnectionState> opener)
      : ctx_(ctx),
        id_(ctx.new_session_id()),
        control_token_(random_hex(kControlTokenBytes)),
        opener_(std::move(opener)),
        link_(std::make_shared<SessionLink>(SessionLink{this})),
        sim_(start(plan, ctx)) {
    ++opener_->sessions_open;
    ctx_.sessions[id_] = this;
    wake_ = ctx_.io.lowLevelProvider->wrapInputFd(
        sim_->wake_fd(), kj::LowLevelAsyncIoProvider::ALREADY_CLOEXEC | kj::LowLevelAsyncIoProvider::ALREADY_NONBLOCK);
    wake_loop_ = watch().eagerlyEvaluate([this](kj::Exception&& e) {
      spdlog::error("session {}: wake-up watch failed: {}", id_, e.getDescription().cStr());
    });
  }

  ~SessionImpl() noexcept(false) {
    ctx_.sessions.erase(id_);
    link_->session = nullptr;  // views and subscriptions see the session gone
    release_slot();
    if (!closed_) ctx_.add_task(end_subscriptions("session closed"));
    wake_loop_ = nullptr;
    wake_ = nullptr;  // the eventfd is watched by one object at a time
    if (sim_->phase() == Phase::starting) {
      // E.g. the client left during openSession: never wait for a start here.
      spdlog::info("session {} closed while starting", id_);
      ctx_.adopt_starting(std::move(sim_));
      return;
    }
    sim_->stop();  // no more wake-ups
    const auto c = sim_->counters();
    spdlog::info("session {} closed after {} ticks ({} blow-ups)", id_, c.ticks, c.blow_ups);
  }

  // Resolves once the model is built; rejects with the error of the start (a scene
  // error, a file refused, a failed build) as the client's message.
  kj::Promise<void> when_ready() {
    check_phase();
    if (phase_ == Phase::ready) return kj::READY_NOW;
    if (phase_ == Phase::failed) fail(error_);
    auto paf = kj::newPromiseAndFulfiller<void>();
    ready_waiters_.add(kj::mv(paf.fulfiller));
    return kj::mv(paf.promise);
  }

  void stop() { sim_->stop(); }
  wire::Session::Client self() { return thisCap(); }
  // Gives the opener's connection its slot back (--max-sessions-per-connection), once.
  void release_slot() {
    if (holds_slot_) --opener_->sessions_open;
    holds_slot_ = false;
  }
  const std::string& control_token() const { return control_token_; }
  const std::shared_ptr<SessionLink>& link() const { return link_; }
  const Simulation& simulation() const { return *sim_; }
  bool closed() const { return closed_; }

  // Every subscriber gets done(reason) and is removed; resolves when each done() was
  // delivered or failed (a vanished client).
  kj::Promise<void> end_subscriptions(const char* reason) {
    kj::Vector<kj::Promise<void>> sent;
    for (auto& sub : subscribers_) sent.add(send_done(sub.sink, reason));
    subscribers_.clear();  // cancels in-flight frames
    if (phase_ == Phase::ready) update_wanted();
    return kj::joinPromises(sent.releaseAsArray());
  }

  // Session.close() and the server's shutdown: the loop stops, subscribers are told.
  kj::Promise<void> close_session(const char* reason) {
    if (closed_) return kj::READY_NOW;
    closed_ = true;
    release_slot();  // a closed session counts against no limit
    if (sim_->phase() != Phase::starting) sim_->stop();
    return end_subscriptions(reason);
  }

  static kj::Promise<void> send_done(wire::FrameSink::Client& sink, const char* reason) {
    auto req = sink.doneRequest();
    req.setReason(reason);
    return req.send().ignoreResult().catch_([](kj::Exception&&) {});
  }

  // `control`: for a control reference (SessionInfo.control), else a read-only view's.
  void fill_info(wire::SessionInfo::Builder info, bool control) {
    KJ_ASSERT(phase_ == Phase::ready);
    info.setControl(control);
    const Model& m = sim_->model();
    const Scene& s = sim_->scene();
    info.setSceneName(s.name);
    info.setParticleCount(static_cast<uint32_t>(m.particle_count));
    info.setDt(s.integrator.dt);
    info.setRateHz(sim_->config().headless ? 0.0 : sim_->config().rate_hz);
    info.setHeadless(sim_->config().headless);
    info.setHapticRateHz(sim_->haptic() ? sim_->haptic()->rate_hz() : 0.0);
    info.setForceLimit(force_limit_);
    auto rest = info.initRestPositions(3 * static_cast<unsigned>(m.particle_count));
    const double* x = m.rest_position.data();
    for (unsigned k = 0; k < rest.size(); ++k) rest.set(k, static_cast<float>(x[k]));
    auto triangles = info.initSurfaceTriangles(3 * static_cast<unsigned>(m.surface_triangles.cols()));
    const int* t = m.surface_triangles.data();
    for (unsigned k = 0; k < triangles.size(); ++k) triangles.set(k, static_cast<uint32_t>(t[k]));
    auto vertices = info.initSurfaceVertices(static_cast<unsigned>(surface_vertices_.size()));
    for (unsigned k = 0; k < vertices.size(); ++k) vertices.set(k, surface_vertices_[k]);
    if (const auto& ref = sim_->reference()) {
      auto copy = [](const std::vector<double>& from, capnp::List<double>::Builder to) {
        for (unsigned k = 0; k < to.size(); ++k) to.set(k, from[k]);
      };
      copy(ref->forces, info.initReferenceForces(static_cast<unsigned>(ref->forces.size())));
      copy(ref->indentation, info.initReferenceIndentation(static_cast<unsigned>(ref->indentation.size())));
      copy(ref->uncertainty, info.initReferenceUncertainty(static_cast<unsigned>(ref->uncertainty.size())));
    }
    info.setTouchHeight(m.touch_height);
    info.setRadius(m.indenter_radius);
    info.setYoungModulus(s.material.young_modulus);
    info.setPoissonRatio(s.material.poisson_ratio);
    info.setBuildSeconds(sim_->build_seconds());
    info.setSessionId(id_);
    set_vec3(info.initWorkspaceMin(), m.tool_workspace_min);
    set_vec3(info.initWorkspaceMax(), m.tool_workspace_max);
    info.setToolMass(sim_->initial_options().indenter_mass);
    info.setGuide(sim_->initial_options().tool_guide == ToolGuide::free ? wire::ToolGuide::FREE
                                                                       : wire::ToolGuide::VERTICAL);
    const DeviceLimits& d = sim_->config().device;
    auto device = info.initDevice();
    device.setMaxStiffness(d.max_stiffness);
    device.setMaxDamping(d.max_damping);
    device.setMaxForce(d.max_force);
    auto coupling = info.initCoupling();
    coupling.setStiffness(coupling_.stiffness);
    coupling.setDamping(coupling_.damping);
  }

  // --- Session methods -----------------------------------------------------

  kj::Promise<void> setForce(SetForceContext context) override {
    check_open("setForce");
    const double f = context.getParams().getNewtons();
    check_force(f, force_limit_);
    auto results = context.getResults();
    results.setSeq(check_queued("setForce", sim_->enqueue(CommandType::set_force, press_down(f))));
    results.setQueuedAtTick(sim_->newest_tick());
    return kj::READY_NOW;
  }

  kj::Promise<void> setForceVector(SetForceVectorContext context) override {
    check_open("setForceVector");
    const Vec3 f = from_wire(context.getParams().getForce());
    check_force_vector(f, force_limit_);
    auto results = context.getResults();
    results.setSeq(check_queued("setForceVector", sim_->enqueue(CommandType::set_force, f)));
    results.setQueuedAtTick(sim_->newest_tick());
    return kj::READY_NOW;
  }

  kj::Promise<void> setPosition(SetPositionContext context) override {
    check_open("setPosition");
    const Vec3 x = from_wire(context.getParams().getPosition());
    const Model& m = sim_->model();
    check_position(x, m.tool_workspace_min, m.tool_workspace_max);
    auto results = context.getResults();
    results.setSeq(check_queued("setPosition", sim_->enqueue(CommandType::set_position, x)));
    results.setQueuedAtTick(sim_->newest_tick());
    return kj::READY_NOW;
  }

  kj::Promise<void> setCoupling(SetCouplingContext context) override {
    check_open("setCoupling");
    const auto c = context.getParams().getCoupling();
    check_coupling("setCoupling: coupling", c.getStiffness(), c.getDamping());
    const CouplingOptions clamped = clamp_to_device({c.getStiffness(), c.getDamping()}, sim_->config().device);
    auto results = context.getResults();
    results.setSeq(check_queued(
        "setCoupling", sim_->enqueue(CommandType::set_coupling, Vec3(clamped.stiffness, clamped.damping, 0.0))));
    coupling_ = clamped;
    auto applied = results.initCoupling();
    applied.setStiffness(clamped.stiffness);
    applied.setDamping(clamped.damping);
    return kj::READY_NOW;
  }

  kj::Promise<void> close(CloseContext) override {
    if (closed_) return kj::READY_NOW;
    spdlog::info("session {} closed by its client", id_);
    return close_session("session closed");
  }

  kj::Promise<void> reset(ResetContext context) override {
    check_open("reset");
    context.getResults().setSeq(check_queued("reset", sim_->enqueue(CommandType::reset)));
    return kj::READY_NOW;
  }

  kj::Promise<void> pause(PauseContext context) override {
    check_open("pause");
    if (sim_->config().headless) fail("pause: a headless session only advances in step()");
    context.getResults().setSeq(check_queued("pause", sim_->enqueue(CommandType::pause)));
    return kj::READY_NOW;
  }

  kj::Promise<void> resume(ResumeContext context) override {
    check_open("resume");
    if (sim_->config().headless) fail("resume: a headless session only advances in step()");
    context.getResults().setSeq(check_queued("resume", sim_->enqueue(CommandType::resume)));
    return kj::READY_NOW;
  }

  kj::Promise<void> subscribe(SubscribeContext context) override;

  kj::Promise<void> step(StepContext context) override {
    check_open("step");
    if (!sim_->config().headless) fail("step: only headless sessions are stepped by the client");
    const uint32_t n = context.getParams().getN();
    check_step_count(n);
    if (job_.get() != nullptr) fail("step: a step() is already running in this session; wait for it");
    const FieldRequest fields = request_of(context.getParams().getFields());
    check_fields("step: fields", fields);
    auto paf = kj::newPromiseAndFulfiller<void>();
    job_ = kj::mv(paf.fulfiller);
    sim_->request_steps(n);
    // A caller that goes mid-job no longer holds the session for the rest of the job
    // (up to 1e6 ticks): when its last reference goes, stop() ends the job at once.
    context.allowCancellation();
    return paf.promise.then([this, context, fields]() mutable {
      const Snapshot& frame = sim_->frames().front();
      fill_frame(context.getResults().initFrame(), frame, fields, derived_for(frame, fields), surface_vertices_);
    });
  }

  kj::Promise<void> stats(StatsContext context) override {
    const SimCounters c = sim_->counters();
    auto s = context.getResults().initStats();
    s.setTicks(c.ticks);
    s.setElapsedSeconds(c.elapsed_s);
    const bool headless = sim_->config().headless;
    s.setTargetRateHz(headless ? 0.0 : sim_->config().rate_hz);
    const double seconds = headless ? c.stepping_s : c.elapsed_s;
    s.setAchievedRateHz(seconds > 0 ? c.ticks / seconds : 0.0);
    fill_percentiles(s.initStepUs(), c.step_us);
    fill_percentiles(s.initLatenessUs(), c.lateness_us);
    s.setDeadlineMisses(c.deadline_misses);
    s.setSkippedTicks(c.skipped_ticks);
    s.setBlowUps(c.blow_ups);
    s.setFramesPublished(c.frames_published);
    s.setFramesCoalesced(c.frames_coalesced);
    s.setRealtimePriority(c.realtime_priority);
    s.setSpinMarginUs(sim_->config().spin_margin_us);
    s.setStiffnessEvaluations(c.stiffness_evaluations);
    s.setMissesLateStart(c.misses_late_start);
    s.setMissesLongStep(c.misses_long_step);
    s.setPinned(c.pinned);
    s.setWatchdogYields(c.watchdog_rests);
    if (HapticRenderer* h = phase_ == Phase::ready ? sim_->haptic() : nullptr) {
      s.setHapticRateHz(h->rate_hz());
      s.setHapticTicks(c.haptic.ticks);
      s.setHapticMisses(c.haptic.misses);
      fill_percentiles(s.initHapticLatenessUs(), c.haptic.lateness_us);
      fill_percentiles(s.initModelAgeUs(), c.haptic.model_age_us);
    }
    auto subs = s.initSubscribers(static_cast<unsigned>(subscribers_.size()));
    unsigned k = 0;
    for (const auto& sub : subscribers_) {
      auto b = subs[k++];
      b.setId(sub.id);
      b.setRateHz(sub.rate_hz);
      b.setSent(sub.sent);
      b.setDropped(sub.dropped);
      b.setInFlight(sub.in_flight);
    }
    return kj::READY_NOW;
  }

  kj::Promise<void> status(StatusContext context) override {
    const SimStatus st = sim_->status();
    auto s = context.getResults().initStatus();
    wire::RunState state = wire::RunState::RUNNING;
    if (st.phase == Phase::starting) state = wire::RunState::STARTING;
    else if (st.phase == Phase::failed) state = wire::RunState::FAILED;
    else if (sim_->config().headless) state = wire::RunState::HEADLESS;
    else if (st.paused) state = wire::RunState::PAUSED;
    s.setState(state);
    s.setTick(st.tick);
    s.setSimTime(st.sim_time);
    s.setForceCommand(st.force_command);
    s.setBlowUps(st.blow_ups);
    s.setLastBlowUp(st.last_blow_up);
    s.setLastBlowUpTick(st.last_blow_up_tick);
    s.setMode(st.position_mode ? wire::ControlMode::POSITION : wire::ControlMode::FORCE);
    s.setClosed(closed_);
    return kj::READY_NOW;
  }

  kj::Promise<void> info(InfoContext context) override {
    fill_info(context.getResults().initInfo(), true);
    return kj::READY_NOW;
  }

  // The subscriber leaves (its handle released, or cancel() with `reason`: then its
  // sink gets done(reason) after the frames already sent).
  void unsubscribe(uint32_t id, const char* reason = nullptr) {
    for (auto it = subscribers_.begin(); it != subscribers_.end(); ++it)
      if (it->id == id) {
        spdlog::debug("session {}: subscriber {} left ({} sent, {} dropped)", id_, id, it->sent, it->dropped);
        if (reason != nullptr) ctx_.add_task(send_done(it->sink, reason));
        subscribers_.erase(it);  // cancels its in-flight send
        break;
      }
    if (phase_ == Phase::ready) update_wanted();
  }

 private:
  struct Subscriber {
    uint32_t id;
    wire::FrameSink::Client sink;
    double rate_hz;
    int64_t interval_ns;
    FieldRequest fields;
    bool in_flight = false;
    bool dead = false;
    int64_t next_due_ns = 0;
    uint64_t sent = 0, dropped = 0;
    kj::Promise<void> pending = nullptr;
  };

  kj::Promise<void> watch() {
    return wake_->tryRead(wake_buffer_, sizeof wake_buffer_, sizeof wake_buffer_).then([this](size_t n) {
      if (n == 0) return kj::Promise<void>(kj::READY_NOW);  // cannot happen for an eventfd
      on_wake();
      return watch();
    });
  }

  static std::unique_ptr<Simulation> start(OpenPlan& plan, ServerContext& ctx) {
    SimConfig config = plan.sim;
    config.cpu = ctx.next_loop_cpu(plan.sim.headless);
    config.rpc_heartbeat = &ctx.heartbeat;
    const ServerOptions& options = ctx.options;
    // Runs on the session's thread; RPC errors become plain exceptions there.
    auto prepare = [plan = std::move(plan), options]() -> Scene {
      try {
        return resolve_scene(plan, options);
      } catch (const kj::Exception& e) {
        throw std::runtime_error(e.getDescription().cStr());
      }
    };
    return std::make_unique<Simulation>(config, std::move(prepare));
  }

  // Every method of a closed session fails (close() itself is idempotent).
  void check_open(const char* method) {
    if (closed_) fail(std::string(method) + ": the session is closed (Session.close)");
  }

  void check_phase() {
    if (phase_ != Phase::starting) return;
    phase_ = sim_->phase();
    if (phase_ == Phase::failed) {
      error_ = sim_->status().error;
    } else if (phase_ == Phase::ready) {
      force_limit_ = force_limit(sim_->scene());
      coupling_ = sim_->initial_coupling();
      const auto& triangles = sim_->model().surface_triangles;
      surface_vertices_.assign(triangles.data(), triangles.data() + triangles.size());
      std::sort(surface_vertices_.begin(), surface_vertices_.end());
      surface_vertices_.erase(std::unique(surface_vertices_.begin(), surface_vertices_.end()), surface_vertices_.end());
      spdlog::info("session {} opened ({}, {}, built in {:.2f} s)", id_, sim_->scene().name,
                   sim_->config().headless ? "headless" : "real-time", sim_->build_seconds());
    }
  }

  void on_wake() {
    if (phase_ == Phase::starting) {
      check_phase();
      if (phase_ != Phase::starting) {
        for (auto& f : ready_waiters_) {
          if (phase_ == Phase::ready) f->fulfill();
          else f->reject(kj::Exception(kj::Exception::Type::FAILED, __FILE__, __LINE__, kj::heapString(error_.c_str())));
        }
        ready_waiters_.clear();
      }
    }
    if (phase_ != Phase::ready) return;
    const bool job_done = sim_->take_job_done();
    const bool fresh = sim_->frames().take();
    if (job_done && job_.get() != nullptr) {
      auto job = kj::mv(job_);
      job_ = nullptr;
      job->fulfill();
    }
    const Snapshot& frame = sim_->frames().front();
    if (fresh && frame.recoveries > logged_blow_ups_) {
      // A blow-up is logged here, on the RPC thread: the simulation thread never logs.
      logged_blow_ups_ = frame.recoveries;
      const SimStatus status = sim_->status();
      spdlog::warn("session {}: blow-up #{} at tick {}: {}", id_, frame.recoveries, status.last_blow_up_tick,
                   status.last_blow_up);
    }
    if (HapticRenderer* haptic = sim_->haptic()) {
      // Multirate: a frame per render tick (its force on the newest step), none per step.
      if (haptic->samples().take()) stream(frame, &haptic->samples().front());
    } else if (fresh) {
      stream(frame);
    }
  }

  void stream(const Snapshot& frame, const HapticSample* render = nullptr) {
    const int64_t now = now_ns();
    bool removed = false;
    for (auto it = subscribers_.begin(); it != subscribers_.end();) {
      Subscriber& sub = *it;
      if (sub.dead) {
        spdlog::debug("session {}: subscriber {} is gone", id_, sub.id);
        it = subscribers_.erase(it);
        removed = true;
        continue;
      }
      ++it;
      if (now < sub.next_due_ns) continue;
      if (sub.in_flight) {  // due but busy: drop this frame (the newest wins next time)
        ++sub.dropped;
        sub.next_due_ns += sub.interval_ns;
        if (sub.next_due_ns < now) sub.next_due_ns = now;
        continue;
      }
      auto req = sub.sink.frameRequest(frame_size_hint(frame, sub.fields, surface_vertices_.size()));
      fill_frame(req.initFrame(), frame, sub.fields, derived_for(frame, sub.fields), surface_vertices_, render);
      sub.in_flight = true;
      ++sub.sent;
      sub.next_due_ns += sub.interval_ns;
      if (sub.next_due_ns < now) sub.next_due_ns = now;
      Subscriber* s = &sub;
      sub.pending = req.send().then([s]() { s->in_flight = false; },
                                    [s](kj::Exception&&) {  // disconnected, or the sink threw
                                      s->in_flight = false;
                                      s->dead = true;
                                    })
                        .eagerlyEvaluate(nullptr);
    }
    if (removed) update_wanted();
  }

  void update_wanted() {
    bool positions = false, contacts = false, derived = false;
    for (const auto& s : subscribers_) {
      positions = positions || s.fields.positions;
      contacts = contacts || s.fields.contacts;
      derived = derived || s.fields.derived();
    }
    sim_->set_wanted(positions, contacts, derived);
  }

  // surfaceOnly needs a surface (SessionInfo.surfaceVertices): refused, naming the field, without.
  void check_fields(const char* field, const FieldRequest& fields) {
    if (fields.surface_only && surface_vertices_.empty())
      fail(std::string(field) + ".surfaceOnly: this session's body has no surface (SessionInfo.surfaceTriangles is "
                                "empty, as for a node_file cloud); ask for every particle instead");
  }

  // The frame's derived fields that `want` asks for, computed now unless they already were for
  // this frame; null when it asks for none or the frame has no double-precision positions yet
  // (a subscriber newer than the frame).
  const DerivedFields* derived_for(const Snapshot& s, const FieldRequest& want) {
    if (!want.derived() || !s.has_body_position) return nullptr;
    DerivedFields& d = derived_;
    if (d.publish_ns != s.publish_ns || d.tick != s.tick) {
      d.publish_ns = s.publish_ns;
      d.tick = s.tick;
      d.has_displacement = d.has_von_mises = false;
    }
    const Model& m = sim_->model();
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

  friend class SubscriptionImpl;
  // All members: RPC thread only (the Simulation's own members say which of its
  // parts the session's thread touches).
  ServerContext& ctx_;
  uint32_t id_;
  std::string control_token_;                // attach() with it gives a control reference (server/access.h)
  std::shared_ptr<ConnectionState> opener_;  // the connection that opened it (sessions_open)
  std::shared_ptr<SessionLink> link_;        // cleared when the session ends
  bool holds_slot_ = true;                   // counted in opener_->sessions_open
  uint32_t logged_blow_ups_ = 0;   // recoveries already logged (on_wake)
  std::unique_ptr<Simulation> sim_;  // declared before the watchers: destroyed after them
  kj::Own<kj::AsyncInputStream> wake_;
  kj::Promise<void> wake_loop_ = nullptr;
  uint8_t wake_buffer_[8] = {};
  Phase phase_ = Phase::starting;  // as last seen on the RPC thread
  std::string error_;              // phase_ == failed
  double force_limit_ = 0.0;       // N, once phase_ == ready
  CouplingOptions coupling_;       // the coupling in effect (SessionInfo.coupling), once ready
  bool closed_ = false;            // Session.close() or the server's shutdown
  std::vector<uint32_t> surface_vertices_;  // SessionInfo.surfaceVertices, once ready
  DerivedFields derived_;                    // of the newest frame that needed them
  kj::Vector<kj::Own<kj::PromiseFulfiller<void>>> ready_waiters_;
  kj::Own<kj::PromiseFulfiller<void>> job_;
  std::list<Subscriber> subscribers_;
};

// Releasing the handle (or losing the connection) unsubscribes. It does not keep the
// session alive (only control references do): when the session ends first, its sink has
// had done() and the handle does nothing.
class SubscriptionImpl final : public wire::Subscription::Server {  // RPC thread only
 public:
  SubscriptionImpl(std::shared_ptr<SessionLink> session, uint32_t id) : session_(std::move(session)), id_(id) {}
  ~SubscriptionImpl() noexcept(false) {
    if (SessionImpl* s = session_->session) s->unsubscribe(id_);
  }

  kj::Promise<void> cancel(CancelContext) override {
    // A second call finds nothing.
    if (SessionImpl* s = session_->session) s->unsubscribe(id_, "subscription cancelled");
    return kj::READY_NOW;
  }

 private:
  std::shared_ptr<SessionLink> session_;
  uint32_t id_;
};

// A read-only view of a session (attach() without the control token): subscribe, stats,
// status and info, forwarded to the session while it lives; every command refused. It
// does not keep the session alive. RPC thread only.
class SessionViewImpl final : public wire::Session::Server {
 public:
  SessionViewImpl(std::shared_ptr<SessionLink> session, uint32_t id) : session_(std::move(session)), id_(id) {}

  kj::Promise<void> subscribe(SubscribeContext context) override { return live("subscribe").subscribe(context); }
  kj::Promise<void> stats(StatsContext context) override { return live("stats").stats(context); }
  kj::Promise<void> status(StatusContext context) override { return live("status").status(context); }
  kj::Promise<void> info(InfoContext context) override {
    live("info").fill_info(context.getResults().initInfo(), false);
    return kj::READY_NOW;
  }

  kj::Promise<void> setForce(SetForceContext) override { refuse("setForce"); }
  kj::Promise<void> setForceVector(SetForceVectorContext) override { refuse("setForceVector"); }
  kj::Promise<void> setPosition(SetPositionContext) override { refuse("setPosition"); }
  kj::Promise<void> setCoupling(SetCouplingContext) override { refuse("setCoupling"); }
  kj::Promise<void> reset(ResetContext) override { refuse("reset"); }
  kj::Promise<void> pause(PauseContext) override { refuse("pause"); }
  kj::Promise<void> resume(ResumeContext) override { refuse("resume"); }
  kj::Promise<void> step(StepContext) override { refuse("step"); }
  kj::Promise<void> close(CloseContext) override { refuse("close"); }

 private:
  SessionImpl& live(const char* method) const {
    if (session_->session == nullptr)
      fail(std::string(method) + ": session " + std::to_string(id_) + " has ended (its owner closed it or left)");
    return *session_->session;
  }
  [[noreturn]] void refuse(const char* method) const {
    fail(std::string(method) + ": this is a read-only view of session " + std::to_string(id_) +
         " (attach() without its control token): it may subscribe and read stats, status and info; commands need "
         "the owner's capability, or attach() with the session's control token");
  }

  std::shared_ptr<SessionLink> session_;
  uint32_t id_;
};

kj::Promise<void> SessionImpl::subscribe(SubscribeContext context) {
  check_open("subscribe");
  auto params = context.getParams();
  auto options = params.getOptions();
  const double rate = options.getRateHz();
  check_subscriber_rate(rate);
  const auto most = static_cast<size_t>(ctx_.options.max_subscribers);
  if (subscribers_.size() >= most)
    fail("subscribe: this session already has " + std::to_string(subscribers_.size()) +
         " subscribers, the server's limit (palpate-server --max-subscribers " + std::to_string(most) + ")");
  const FieldRequest fields = request_of(options.getFields());
  check_fields("subscribe: options.fields", fields);
  Subscriber sub{ctx_.next_subscriber_id++, params.getSink(), rate, rate > 0.0 ? static_cast<int64_t>(1e9 / rate) : 0,
                 fields};
  sub.next_due_ns = now_ns();
  const uint32_t id = sub.id;
  subscribers_.push_back(kj::mv(sub));
  update_wanted();
  spdlog::debug("session {}: subscriber {} at {} Hz", id_, id, rate);
  context.getResults().setSubscription(kj::heap<SubscriptionImpl>(link_, id));
  return kj::READY_NOW;
}

// ---------------------------------------------------------------------------
// ServerImpl

kj::Promise<void> ServerImpl::version(VersionContext context) {
  context.getResults().setProtocolVersion(wire::PROTOCOL_VERSION);
  context.getResults().setServer("palpate-server 0.1");
  return kj::READY_NOW;
}

void ServerImpl::check_authenticated(const char* method) const {
  if (!authenticated_)
    fail(std::string(method) +
         ": this server requires an access token: call PalpateServer.authenticate(accessToken) first and use the "
         "capability it returns (palpate-server --access-token-file)");
}

kj::Promise<void> ServerImpl::authenticate(AuthenticateContext context) {
  const std::string& expected = ctx_.options.access_token;
  if (!expected.empty()) {
    ctx_.check_guesses_left(*connection_, "authenticate");
    const auto token = context.getParams().getAccessToken();
    if (!tokens_equal(std::string_view(token.begin(), token.size()), expected))
      return ctx_.refuse_guess(*connection_, "authenticate: accessToken: not this server's access token");
  }
  context.getResults().setServer(kj::heap<ServerImpl>(ctx_, connection_, true));
  return kj::READY_NOW;
}

kj::Promise<void> ServerImpl::listScenes(ListScenesContext context) {
  check_authenticated("listScenes");
  const auto names = scene_names(ctx_.options.scene_dir);
  auto list = context.getResults().initNames(static_cast<unsigned>(names.size()));
  for (unsigned k = 0; k < names.size(); ++k) list.set(k, names[k]);
  return kj::READY_NOW;
}

// Without a token: a read-only view (SessionViewImpl). With the session's control token: its
// control capability. An unknown id or a wrong token: refused after a delay, and counted.
kj::Promise<void> ServerImpl::attach(AttachContext context) {
  check_authenticated("attach");
  ctx_.check_guesses_left(*connection_, "attach");
  const uint32_t id = context.getParams().getSessionId();
  const auto token = context.getParams().getControlToken();
  const auto it = ctx_.sessions.find(id);
  if (it == ctx_.sessions.end())
    return ctx_.refuse_guess(*connection_, "attach: sessionId: no live session " + std::to_string(id));
  SessionImpl& session = *it->second;
  const bool control = token.size() > 0;
  if (control && !tokens_equal(std::string_view(token.begin(), token.size()), session.control_token()))
    return ctx_.refuse_guess(*connection_, "attach: controlToken: not the control token of session " +
                                               std::to_string(id) + " (leave it empty for a read-only view)");
  wire::Session::Client cap = control ? session.self() : kj::heap<SessionViewImpl>(session.link(), id);
  context.allowCancellation();  // waiting for a start holds nothing worth finishing
  auto ready = session.when_ready();
  return ready.then([context, cap = kj::mv(cap), link = session.link(), control]() mutable {
    if (link->session == nullptr) fail("attach: the session ended while it was starting");
    auto results = context.getResults();
    link->session->fill_info(results.initInfo(), control);
    results.setSession(kj::mv(cap));
  });
}

// Never blocks the event loop: only the cheap checks run here; the scene is
// validated, its files read and its model built on the session's thread, and the
// call resolves (or rejects with that thread's message) when it is done.
kj::Promise<void> ServerImpl::openSession(OpenSessionContext context) {
  check_authenticated("openSession");
  // Closed sessions whose capabilities are still held count against no limit.
  size_t running = ctx_.closing_sessions();
  for (const auto& [id, s] : ctx_.sessions) running += s->closed() ? 0 : 1;
  if (static_cast<int>(running) >= ctx_.options.max_sessions)
    fail("openSession: the server already runs " + std::to_string(running) +
         " sessions, its limit (palpate-server --max-sessions " + std::to_string(ctx_.options.max_sessions) + ")");
  if (connection_->sessions_open >= ctx_.options.max_sessions_per_connection)
    fail("openSession: this connection already has " + std::to_string(connection_->sessions_open) +
         " live sessions, the limit per connection (palpate-server --max-sessions-per-connection " +
         std::to_string(ctx_.options.max_sessions_per_connection) + "): close one first");
  OpenPlan plan = plan_session(context.getParams().getRequest(), ctx_.options);
  context.allowCancellation();  // a caller that cancels or disconnects drops the start (below)

  auto impl = kj::heap<SessionImpl>(ctx_, std::move(plan), connection_);
  SessionImpl& session = *impl;
  wire::Session::Client cap = kj::mv(impl);
  auto ready = session.when_ready();
  // If the caller goes meanwhile, this promise is dropped with `cap`: the session,
  // still starting, is cancelled and handed to ctx_.adopt_starting (no wait here).
  return ready.then([context, cap = kj::mv(cap), &session]() mutable {
    auto results = context.getResults();
    session.fill_info(results.initInfo(), true);
    results.setControlToken(session.control_token());
    results.setSession(kj::mv(cap));
  });
}

capnp::Capability::Client ServerContext::bootstrap_for_connection() {
  return kj::heap<ServerImpl>(*this, std::make_shared<ConnectionState>(), options.access_token.empty());
}

uint32_t ServerContext::new_session_id() const {
  uint32_t id = random_session_id();
  while (sessions.count(id) != 0) id = random_session_id();
  return id;
}

void ServerContext::check_guesses_left(const ConnectionState& connection, const char* method) const {
  if (connection.wrong_tokens >= options.max_wrong_tokens)
    fail(std::string(method) + ": this connection was refused " + std::to_string(connection.wrong_tokens) +
         " tokens or session ids, its limit (palpate-server --max-wrong-tokens " +
         std::to_string(options.max_wrong_tokens) + "): it may try no more");
}

kj::Promise<void> ServerContext::refuse_guess(ConnectionState& connection, std::string message) {
  ++connection.wrong_tokens;
  spdlog::info("refused: {}", message);  // names the method and the id, never a token
  return io.provider->getTimer()
      .afterDelay(options.wrong_token_delay_ms * kj::MILLISECONDS)
      .then([message = std::move(message)]() { fail(message); });
}

void ServerContext::stop_all() {
  for (auto& [id, s] : sessions) s->stop();
  for (Closing* c : closing_) c->sim->stop();
}

int ServerContext::next_loop_cpu(bool headless) {
  const int cores = static_cast<int>(std::thread::hardware_concurrency());
  if (headless || !options.pin_threads || cores < 2) return -1;
  const int cpu = 1 + next_loop_core_ % (cores - 1);  // core 0 keeps the RPC thread and the workers
  ++next_loop_core_;
  return cpu;
}

Probe ServerContext::health_probe(HealthWindow& window, double min_rate_fraction, double max_miss_fraction) {
  Probe probe;
  std::map<uint32_t, HealthWindow::Sample> samples;
  int realtime = 0;
  for (const auto& [id, s] : sessions) {
    const Simulation& sim = s->simulation();
    if (s->closed() || sim.config().headless || sim.phase() != Phase::ready || sim.status().paused) continue;
    ++realtime;
    const SimCounters c = sim.counters();
    HealthWindow::Sample now{c.ticks, c.elapsed_s, c.deadline_misses, ""};
    // Over the time since this window's previous probe (or since the session started).
    HealthWindow::Sample before{};
    const auto it = window.samples_.find(id);
    if (it != window.samples_.end()) before = it->second;
    const double seconds = now.elapsed_s - before.elapsed_s, target = sim.config().rate_hz;
    if (seconds < kMinJudgedSeconds || seconds * target < kMinJudgedTicks) {
      // Too short to judge: the previous verdict stands; the longer interval is judged next time.
      if (it != window.samples_.end()) samples[id] = before;
      now.failure = before.failure;
    } else {
      const double ticks = static_cast<double>(now.ticks - before.ticks);
      const double rate = ticks / seconds;
      const double misses =
          ticks > 0 ? static_cast<double>(now.deadline_misses - before.deadline_misses) / ticks : 1.0;
      if (rate < min_rate_fraction * target || misses > max_miss_fraction)
        now.failure = "session " + std::to_string(id) + ": " + std::to_string(rate) + " Hz of " +
                      std::to_string(target) + " Hz, deadline misses " + std::to_string(100.0 * misses) + " %; ";
      samples[id] = now;
    }
    if (!now.failure.empty()) {
      probe.ok = false;
      probe.detail += now.failure;
    }
  }
  window.samples_ = std::move(samples);
  if (probe.ok) probe.detail = "ok: " + std::to_string(realtime) + " real-time session(s) hold their rate";
  return probe;
}

kj::Promise<void> ServerContext::close_all(const char* reason) {
  kj::Vector<kj::Promise<void>> closing;
  for (auto& [id, s] : sessions) closing.add(s->close_session(reason));
  return kj::joinPromises(closing.releaseAsArray());
}

}  // namespace palpate::server
