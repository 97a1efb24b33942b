// One session on the RPC thread (server/session.h): its RPC methods, streaming to its
// subscribers, and its read-only views.
#include "server/session.h"

#include <algorithm>
#include <stdexcept>

#include <kj/debug.h>
#include <spdlog/spdlog.h>

#include "server/rpc_server.h"

namespace palpate::server {

SessionImpl::SessionImpl(ServerContext& ctx, OpenPlan plan, std::shared_ptr<ConnectionState> opener)
    : ctx_(ctx), id_(ctx.new_session_id()), control_token_(random_hex(kControlTokenBytes)), opener_(std::move(opener)), link_(std::make_shared<SessionLink>(SessionLink{this})), sim_(start(plan, ctx)) {
  ++opener_->sessions_open;
  ctx_.sessions[id_] = this;
  wake_ = ctx_.io.lowLevelProvider->wrapInputFd(
      sim_->wake_fd(), kj::LowLevelAsyncIoProvider::ALREADY_CLOEXEC | kj::LowLevelAsyncIoProvider::ALREADY_NONBLOCK);
  wake_loop_ = watch().eagerlyEvaluate([this](kj::Exception&& e) {
    spdlog::error("session {}: wake-up watch failed: {}", id_, e.getDescription().cStr());
  });
}

SessionImpl::~SessionImpl() noexcept(false) {
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

kj::Promise<void> SessionImpl::when_ready() {
  check_phase();
  if (phase_ == Phase::ready) return kj::READY_NOW;
  if (phase_ == Phase::failed) fail(error_);
  auto paf = kj::newPromiseAndFulfiller<void>();
  ready_waiters_.add(kj::mv(paf.fulfiller));
  return kj::mv(paf.promise);
}

void SessionImpl::release_slot() {
  if (holds_slot_) --opener_->sessions_open;
  holds_slot_ = false;
}

kj::Promise<void> SessionImpl::end_subscriptions(const char* reason) {
  kj::Vector<kj::Promise<void>> sent;
  for (auto& sub : subscribers_) sent.add(send_done(sub.sink, reason));
  subscribers_.clear();  // cancels in-flight frames
  if (phase_ == Phase::ready) update_wanted();
  return kj::joinPromises(sent.releaseAsArray());
}

kj::Promise<void> SessionImpl::close_session(const char* reason) {
  if (closed_) return kj::READY_NOW;
  closed_ = true;
  release_slot();  // a closed session counts against no limit
  if (sim_->phase() != Phase::starting) sim_->stop();
  return end_subscriptions(reason);
}

kj::Promise<void> SessionImpl::send_done(wire::FrameSink::Client& sink, const char* reason) {
  auto req = sink.doneRequest();
  req.setReason(reason);
  return req.send().ignoreResult().catch_([](kj::Exception&&) {});
}

void SessionImpl::fill_info(wire::SessionInfo::Builder info, bool control) {
  KJ_ASSERT(phase_ == Phase::ready);
  info.setControl(control);
  const Model& m = sim_->shown_model();
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

kj::Promise<void> SessionImpl::setForce(SetForceContext context) {
  check_open("setForce");
  const double f = context.getParams().getNewtons();
  check_force(f, force_limit_);
  auto results = context.getResults();
  results.setSeq(check_queued("setForce", sim_->enqueue(CommandType::set_force, press_down(f))));
  results.setQueuedAtTick(sim_->newest_tick());
  return kj::READY_NOW;
}

kj::Promise<void> SessionImpl::setForceVector(SetForceVectorContext context) {
  check_open("setForceVector");
  const Vec3 f = from_wire(context.getParams().getForce());
  check_force_vector(f, force_limit_);
  auto results = context.getResults();
  results.setSeq(check_queued("setForceVector", sim_->enqueue(CommandType::set_force, f)));
  results.setQueuedAtTick(sim_->newest_tick());
  return kj::READY_NOW;
}

kj::Promise<void> SessionImpl::setPosition(SetPositionContext context) {
  check_open("setPosition");
  const Vec3 x = from_wire(context.getParams().getPosition());
  const Model& m = sim_->shown_model();
  check_position(x, m.tool_workspace_min, m.tool_workspace_max);
  auto results = context.getResults();
  results.setSeq(check_queued("setPosition", sim_->enqueue(CommandType::set_position, x)));
  results.setQueuedAtTick(sim_->newest_tick());
  return kj::READY_NOW;
}

kj::Promise<void> SessionImpl::setCoupling(SetCouplingContext context) {
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

kj::Promise<void> SessionImpl::close(CloseContext) {
  if (closed_) return kj::READY_NOW;
  spdlog::info("session {} closed by its client", id_);
  return close_session("session closed");
}

kj::Promise<void> SessionImpl::reset(ResetContext context) {
  check_open("reset");
  context.getResults().setSeq(check_queued("reset", sim_->enqueue(CommandType::reset)));
  return kj::READY_NOW;
}

kj::Promise<void> SessionImpl::pause(PauseContext context) {
  check_open("pause");
  if (sim_->config().headless) fail("pause: a headless session only advances in step()");
  context.getResults().setSeq(check_queued("pause", sim_->enqueue(CommandType::pause)));
  return kj::READY_NOW;
}

kj::Promise<void> SessionImpl::resume(ResumeContext context) {
  check_open("resume");
  if (sim_->config().headless) fail("resume: a headless session only advances in step()");
  context.getResults().setSeq(check_queued("resume", sim_->enqueue(CommandType::resume)));
  return kj::READY_NOW;
}

kj::Promise<void> SessionImpl::step(StepContext context) {
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

kj::Promise<void> SessionImpl::stats(StatsContext context) {
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
  s.setRefocuses(static_cast<uint64_t>(c.refocuses));
  s.setRefocusesDropped(static_cast<uint64_t>(c.refocuses_dropped));
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

kj::Promise<void> SessionImpl::status(StatusContext context) {
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

kj::Promise<void> SessionImpl::info(InfoContext context) {
  fill_info(context.getResults().initInfo(), true);
  return kj::READY_NOW;
}

void SessionImpl::unsubscribe(uint32_t id, const char* reason) {
  for (auto it = subscribers_.begin(); it != subscribers_.end(); ++it)
    if (it->id == id) {
      spdlog::debug("session {}: subscriber {} left ({} sent, {} dropped)", id_, id, it->sent, it->dropped);
      if (reason != nullptr) ctx_.add_task(send_done(it->sink, reason));
      subscribers_.erase(it);  // cancels its in-flight send
      break;
    }
  if (phase_ == Phase::ready) update_wanted();
}

kj::Promise<void> SessionImpl::watch() {
  return wake_->tryRead(wake_buffer_, sizeof wake_buffer_, sizeof wake_buffer_).then([this](size_t n) {
    if (n == 0) return kj::Promise<void>(kj::READY_NOW);  // cannot happen for an eventfd
    on_wake();
    return watch();
  });
}

std::unique_ptr<Simulation> SessionImpl::start(OpenPlan& plan, ServerContext& ctx) {
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

void SessionImpl::check_open(const char* method) {
  if (closed_) fail(std::string(method) + ": the session is closed (Session.close)");
}

void SessionImpl::check_phase() {
  if (phase_ != Phase::starting) return;
  phase_ = sim_->phase();
  if (phase_ == Phase::failed) {
    error_ = sim_->status().error;
  } else if (phase_ == Phase::ready) {
    force_limit_ = force_limit(sim_->scene());
    coupling_ = sim_->initial_coupling();
    const auto& triangles = sim_->shown_model().surface_triangles;
    surface_vertices_.assign(triangles.data(), triangles.data() + triangles.size());
    std::sort(surface_vertices_.begin(), surface_vertices_.end());
    surface_vertices_.erase(std::unique(surface_vertices_.begin(), surface_vertices_.end()), surface_vertices_.end());
    spdlog::info("session {} opened ({}, {}, built in {:.2f} s)", id_, sim_->scene().name,
                 sim_->config().headless ? "headless" : "real-time", sim_->build_seconds());
  }
}

void SessionImpl::on_wake() {
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
  if (fresh && frame.refocuses_dropped > logged_drops_) {
    logged_drops_ = frame.refocuses_dropped;
    spdlog::info("session {}: refocus dropped (#{}): {}", id_, frame.refocuses_dropped,
                 sim_->status().last_refocus_drop);
  }
  if (HapticRenderer* haptic = sim_->haptic()) {
    // Multirate: a frame per render tick (its force on the newest step), none per step.
    if (haptic->samples().take()) stream(frame, &haptic->samples().front());
  } else if (fresh) {
    stream(frame);
  }
}

void SessionImpl::stream(const Snapshot& frame, const HapticSample* render) {
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

void SessionImpl::update_wanted() {
  bool positions = false, contacts = false, derived = false;
  for (const auto& s : subscribers_) {
    positions = positions || s.fields.positions;
    contacts = contacts || s.fields.contacts;
    derived = derived || s.fields.derived();
  }
  sim_->set_wanted(positions, contacts, derived);
}

void SessionImpl::check_fields(const char* field, const FieldRequest& fields) {
  if (fields.surface_only && surface_vertices_.empty())
    fail(std::string(field) + ".surfaceOnly: this session's body has no surface (SessionInfo.surfaceTriangles is "
                              "empty, as for a node_file cloud); ask for every particle instead");
}

const DerivedFields* SessionImpl::derived_for(const Snapshot& s, const FieldRequest& want) {
  return derived_fields(sim_->shown_model(), s, want, derived_);
}



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

wire::Session::Client read_only_view(std::shared_ptr<SessionLink> link, uint32_t id) {
  return kj::heap<SessionViewImpl>(std::move(link), id);
}

}  // namespace palpate::server
