#include "core/integrators.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include "core/mls_forces.h"
#include "core/solid.h"

namespace palpate {

void add_contact_forces(const State& state, Points& force) {
  for (size_t c = 0; c < state.contact_index.size(); ++c)
    force.col(state.contact_index[c]) += state.contact_force.col(static_cast<Eigen::Index>(c));
}

namespace {

// Acceleration of particle i from its total force f_i (3 doubles) and velocity v_i:
// a_i = f_i / m_i - c v_i + g for a free particle, zero for a fixed one.
struct Acceleration {
  const double* inverse_mass;
  double damping;
  Vec3 gravity;
  Acceleration(const Model& model, const Options& opt)
      : inverse_mass(model.inverse_mass.data()), damping(opt.integrator.damping), gravity(opt.gravity) {}
  Vec3 operator()(int i, const double* f, const double* v) const {
    const double inv_m = inverse_mass[i];
    if (inv_m == 0.0) return Vec3::Zero();
    return Vec3(inv_m * f[0] - damping * v[0] + gravity[0], inv_m * f[1] - damping * v[1] + gravity[1],
                inv_m * f[2] - damping * v[2] + gravity[2]);
  }
};

// The fused update loops below run over groups of four consecutive particles, whose
// twelve coordinates (x0 y0 z0 x1 | y1 z1 x2 y2 | z2 x3 y3 z3) are three Lanes (GCC/Clang
// vector extension: AVX2/FMA or SSE pairs), and over the remaining particles one
// coordinate at a time; the per-coordinate formulas are templates on double / Lanes.
constexpr int kGroup = 4;
using Lanes = double __attribute__((vector_size(kGroup * sizeof(double))));

template <class T>
inline T load(const double* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <class T>
inline void store(double* p, const T& v) {
  std::memcpy(p, &v, sizeof v);
}

// Accelerations of the group of particles 4p ... 4p+3 (Acceleration, four at a time).
inline void group_accelerations(const Acceleration& acc, int p, const double* f, const double* v, Lanes (&a)[3]) {
  const double* m = acc.inverse_mass + kGroup * p;
  const double free[kGroup] = {m[0] != 0.0 ? 1.0 : 0.0, m[1] != 0.0 ? 1.0 : 0.0, m[2] != 0.0 ? 1.0 : 0.0,
                               m[3] != 0.0 ? 1.0 : 0.0};
  const Lanes inv_m[3] = {Lanes{m[0], m[0], m[0], m[1]}, Lanes{m[1], m[1], m[2], m[2]}, Lanes{m[2], m[3], m[3], m[3]}};
  const Lanes is_free[3] = {Lanes{free[0], free[0], free[0], free[1]}, Lanes{free[1], free[1], free[2], free[2]},
                            Lanes{free[2], free[3], free[3], free[3]}};
  const Vec3& g = acc.gravity;
  const Lanes gravity[3] = {Lanes{g[0], g[1], g[2], g[0]}, Lanes{g[1], g[2], g[0], g[1]}, Lanes{g[2], g[0], g[1], g[2]}};
  for (int q = 0; q < 3; ++q) {
    const int k = 3 * kGroup * p + kGroup * q;
    a[q] = inv_m[q] * load<Lanes>(f + k) + is_free[q] * (gravity[q] - acc.damping * load<Lanes>(v + k));
  }
}

}  // namespace

void particle_accelerations(const Model& model, const Options& opt, const State& state, const Points& x,
                            const Points& v, Points& force, Points& acceleration) {
  elastic_forces(model, x, force);
  add_contact_forces(state, force);
  const Acceleration accel(model, opt);
  for (int i = 0; i < model.particle_count; ++i)
    acceleration.col(i) = accel(i, force.col(i).data(), v.col(i).data());
}

Vec3 indenter_free_acceleration(const Options& opt, const State& state) {
  const Vec3 a = (state.indenter_contact_force + state.force_command) / opt.indenter_mass + opt.gravity;
  return a.cwiseProduct(tool_axes(opt));  // a guided axis takes no acceleration
}

double tool_effective_mass(const Options& opt) {
  const double dt = opt.integrator.dt;
  const CouplingOptions& c = opt.coupling;
  return c.stiffness > 0.0 ? opt.indenter_mass + dt * c.damping + dt * dt * c.stiffness : opt.indenter_mass;
}

void tool_free_motion(const Model& model, const Options& opt, State& state) {
  const double dt = opt.integrator.dt;
  const CouplingOptions& c = opt.coupling;
  const Vec3 axes = tool_axes(opt);
  Vec3& x = state.indenter_center;
  Vec3& v = state.indenter_velocity;
  if (c.stiffness > 0.0) {
    // (M + dt b + dt^2 k) v' = M v + dt [F + M g + k (T - x)],  x' = x + dt v'   (2.6)
    const Vec3 load = state.indenter_contact_force + state.force_command + opt.indenter_mass * opt.gravity +
                      c.stiffness * (state.tool_target - x);
    v = ((opt.indenter_mass * v + dt * load) / tool_effective_mass(opt)).cwiseProduct(axes);
  } else {
    v += dt * indenter_free_acceleration(opt, state);
  }
  x += dt * v;
  keep_tool_in_workspace(model, state);
  state.out.coupling_force =
      c.stiffness > 0.0 ? Vec3(c.stiffness * (state.tool_target - x) - c.damping * v) : Vec3::Zero();
}

void keep_tool_in_workspace(const Model& model, State& state) {
  for (int a = 0; a < 3; ++a) {
    double& c = state.indenter_center[a];
    double& v = state.indenter_velocity[a];
    if (c < model.tool_workspace_min[a]) {
      c = model.tool_workspace_min[a];
      v = std::max(v, 0.0);
    } else if (c > model.tool_workspace_max[a]) {
      c = model.tool_workspace_max[a];
      v = std::min(v, 0.0);
    }
  }
}

namespace {

// RK4's tool: under a constant force over the step, integrated exactly; with the
// coupling on, the implicit step of tool_free_motion.
void indenter_free_motion(const Model& model, const Options& opt, State& state, double dt) {
  if (opt.coupling.stiffness > 0.0) return tool_free_motion(model, opt, state);
  state.out.coupling_force.setZero();
  const Vec3 a = indenter_free_acceleration(opt, state);
  state.indenter_center += dt * state.indenter_velocity + 0.5 * dt * dt * a;
  state.indenter_velocity += dt * a;
  keep_tool_in_workspace(model, state);
}

}  // namespace

namespace {

struct MotionSums;

// One RK4 stage at coordinate k (T = double or Lanes): with the stage's velocity v_s and
// acceleration a_s, add k_s = (v_s, a_s) with its weight to the sums and form the next
// stage x_{s+1} = x_0 + h v_s, v_{s+1} = v_0 + h a_s. v_stage may be the stage's own input.
struct Rk4Stage {
  const double* x0;
  const double* v0;
  const double* v_in;  // v_s
  double* x_sum;
  double* v_sum;
  double* x_next;
  double* v_next;
  double h, weight;
  bool first;
  MotionSums* sums = nullptr;  // none taken (the update passes' common interface)
  template <class T>
  void operator()(int k, const T& a, const T& /*mass*/) const {
    const T v = load<T>(v_in + k);
    store(x_sum + k, first ? v : load<T>(x_sum + k) + weight * v);
    store(v_sum + k, first ? a : load<T>(v_sum + k) + weight * a);
    store(x_next + k, load<T>(x0 + k) + h * v);
    store(v_next + k, load<T>(v0 + k) + h * a);
  }
};

// Sums the health checks need (health.h), taken in the last update pass while the
// new values are in registers: sum m v^2 and sum x over the coordinates.
struct MotionSums {
  Lanes kinetic_lanes = {}, position_lanes = {};
  double kinetic = 0.0, position = 0.0;
  void add(const Lanes& m, const Lanes& v, const Lanes& x) {
    kinetic_lanes += m * v * v;
    position_lanes += x;
  }
  void add(double m, double v, double x) {
    kinetic += m * v * v;
    position += x;
  }
  void add(const MotionSums& o) {
    kinetic_lanes += o.kinetic_lanes;
    position_lanes += o.position_lanes;
    kinetic += o.kinetic;
    position += o.position;
  }
  void write(StepOutputs& w) const {
    w.free_motion_kinetic = 0.5 * (kinetic + (kinetic_lanes[0] + kinetic_lanes[1]) + (kinetic_lanes[2] + kinetic_lanes[3]));
    w.free_motion_position_sum = position + (position_lanes[0] + position_lanes[1]) + (position_lanes[2] + position_lanes[3]);
    w.free_motion_sums_valid = true;
  }
};

// The last stage and the update x += dt/6 (k_1 + 2 k_2 + 2 k_3 + k_4), likewise for v.
struct Rk4Update {
  const double* v4;
  const double* x_sum;
  const double* v_sum;
  double* x;
  double* v;
  double dt_6;
  MotionSums* sums;
  template <class T>
  void operator()(int k, const T& a, const T& mass) const {
    const T x_new = load<T>(x + k) + dt_6 * (load<T>(x_sum + k) + load<T>(v4 + k));
    const T v_new = load<T>(v + k) + dt_6 * (load<T>(v_sum + k) + a);
    store(x + k, x_new);
    store(v + k, v_new);
    sums->add(mass, v_new, x_new);
  }
};

// Symplectic Euler at coordinate k: v += dt a; x += dt v.
struct SymplecticEulerUpdate {
  double* x;
  double* v;
  double dt;
  MotionSums* sums;
  template <class T>
  void operator()(int k, const T& a, const T& mass) const {
    const T v_new = load<T>(v + k) + dt * a;
    const T x_new = load<T>(x + k) + dt * v_new;
    store(v + k, v_new);
    store(x + k, x_new);
    sums->add(mass, v_new, x_new);
  }
};

// Calls update(k, a_k, m_k) for every coordinate k with the acceleration a(f, v) there
// and the particle's mass, over particles [begin, end) (begin a multiple of kGroup: groups
// of four first, then the rest one by one).
template <class Update>
void accelerations_in_range(const Acceleration& accel, const Model& model, int begin, int end, const double* f,
                            const double* v, const Update& update) {
  const int groups_end = begin + (end - begin) / kGroup * kGroup;
  const double* mass = model.mass.data();
  for (int i0 = begin; i0 < groups_end; i0 += kGroup) {
    const int p = i0 / kGroup;
    Lanes a[3];
    group_accelerations(accel, p, f, v, a);
    const double* m = mass + kGroup * p;
    const Lanes m_lanes[3] = {Lanes{m[0], m[0], m[0], m[1]}, Lanes{m[1], m[1], m[2], m[2]}, Lanes{m[2], m[3], m[3], m[3]}};
    for (int q = 0; q < 3; ++q) update(3 * kGroup * p + kGroup * q, a[q], m_lanes[q]);
  }
  for (int i = groups_end; i < end; ++i) {
    const Vec3 a = accel(i, f + 3 * i, v + 3 * i);
    for (int c = 0; c < 3; ++c) update(3 * i + c, a[c], mass[i]);
  }
}

// accelerations_in_range over every particle; on the threads' pool when there is one:
// thread t takes a contiguous range of whole groups (the last one the remaining particles
// too) with sums of its own, added into update.sums in the order t = 0, 1, ... Each
// coordinate's update is the same arithmetic for any thread count; only the sums' rounding
// depends on it.
template <class Update>
void for_each_acceleration(const Model& model, const Options& opt, const double* f, const double* v,
                           const Update& update, WorkerThreads& threads) {
  const Acceleration accel(model, opt);
  const int n = model.particle_count, T = threads.count();
  if (T == 1) return accelerations_in_range(accel, model, 0, n, f, v, update);
  const int groups = n / kGroup;
  MotionSums partial[kMaxThreads];
  threads.pool->run([&](int t) {
    Update own = update;
    if (update.sums) own.sums = &partial[t];
    const int begin = kGroup * (groups * t / T), end = t + 1 == T ? n : kGroup * (groups * (t + 1) / T);
    accelerations_in_range(accel, model, begin, end, f, v, own);
  });
  if (update.sums)
    for (int t = 0; t < T; ++t) update.sums->add(partial[t]);
}

}  // namespace

void free_motion_rk4(const Model& model, const Options& opt, State& state) {
  // Classical RK4 on y = (x, v), y' = (v, a(x, v)), with the stages fused: one pass
  // over the coordinates per stage takes k_s = (v_s, a_s) from the forces at x_s,
  // adds it to the weighted sum k_1 + 2 k_2 + 2 k_3 and forms the next stage
  // (x_{s+1}, v_{s+1}) = (x_0, v_0) + h_{s+1} k_s, h = (dt/2, dt/2, dt); the fourth
  // pass applies the update. state.position, state.velocity hold (x_0, v_0) until then.
  const double dt = opt.integrator.dt;
  Workspace& w = state.work;
  Points& x_stage = w.rk_x[0];  // x_s
  Points& v_stage = w.rk_v[0];  // v_s
  Points& x_sum = w.rk_x[1];    // weighted sum of the position slopes so far
  Points& v_sum = w.rk_v[1];    // weighted sum of the velocity slopes so far
  const double next_h[3] = {0.5 * dt, 0.5 * dt, dt};
  const double weight[3] = {1.0, 2.0, 2.0};
  for (int s = 0; s < 3; ++s) {
    const Points& x_s = s == 0 ? state.position : x_stage;
    const Points& v_s = s == 0 ? state.velocity : v_stage;
    elastic_forces(model, x_s, w.force, w.threads);
    add_contact_forces(state, w.force);
    const Rk4Stage stage{state.position.data(), state.velocity.data(), v_s.data(), x_sum.data(), v_sum.data(),
                         x_stage.data(), v_stage.data(), next_h[s], weight[s], s == 0};
    for_each_acceleration(model, opt, w.force.data(), v_s.data(), stage, w.threads);
  }
  elastic_forces(model, x_stage, w.force, w.threads);
  add_contact_forces(state, w.force);
  MotionSums sums;
  const Rk4Update update{v_stage.data(), x_sum.data(), v_sum.data(), state.position.data(), state.velocity.data(),
                         dt / 6.0, &sums};
  for_each_acceleration(model, opt, w.force.data(), v_stage.data(), update, w.threads);
  sums.write(state.out);
  indenter_free_motion(model, opt, state, dt);
}

void free_motion_symplectic_euler(const Model& model, const Options& opt, State& state) {
  const double dt = opt.integrator.dt;
  Workspace& w = state.work;
  elastic_forces(model, state.position, w.force, w.threads);
  add_contact_forces(state, w.force);
  MotionSums sums;
  const SymplecticEulerUpdate update{state.position.data(), state.velocity.data(), dt, &sums};
  for_each_acceleration(model, opt, w.force.data(), state.velocity.data(), update, w.threads);
  sums.write(state.out);
  tool_free_motion(model, opt, state);
}

void free_motion_multirate_symplectic_euler(const Model& model, const Options& opt, State& state) {
  const RateSchedule& s = model.rate_schedule;
  Workspace& w = state.work;
  const int n = model.particle_count;
  const int64_t tick = state.tick;
  const int p = static_cast<int>(tick % s.period);
  assert(state.elastic_update_tick.size() == static_cast<size_t>(n) && w.subcycle_block_listed.size() == s.block_ticks.size());
  // The coarse particles near the tool update at every tick: the blocks of their domains that
  // the tick's schedule lacks are added to it.
  w.subcycle_near.clear();
  w.subcycle_extra.clear();
  const Vec3 centre = state.indenter_center;
  for (int i = 0; i < n; ++i) {
    if (s.interval[i] == 1 || model.fixed[i]) continue;
    const double reach = model.indenter_radius + kSubcyclingReach * model.support_radius[i];
    if ((state.position.col(i) - centre).squaredNorm() >= reach * reach) continue;
    w.subcycle_near.push_back(i);
    for (int a = s.particle_block_offset[i]; a < s.particle_block_offset[i + 1]; ++a) {
      const int b = s.particle_block_index[a];
      if ((s.block_ticks[b] >> p & 1) || w.subcycle_block_listed[b]) continue;
      w.subcycle_block_listed[b] = 1;
      w.subcycle_extra.push_back(b);
    }
  }
  for (int b : w.subcycle_extra) w.subcycle_block_listed[b] = 0;
  const int* blocks = s.block_index.data() + s.block_offset[p];
  int count = s.block_offset[p + 1] - s.block_offset[p];
  if (!w.subcycle_extra.empty()) {
    std::sort(w.subcycle_extra.begin(), w.subcycle_extra.end());
    w.subcycle_blocks.resize(count + w.subcycle_extra.size());
    std::merge(blocks, blocks + count, w.subcycle_extra.begin(), w.subcycle_extra.end(), w.subcycle_blocks.begin());
    blocks = w.subcycle_blocks.data();
    count = static_cast<int>(w.subcycle_blocks.size());
  }
  mls_internal_forces_of_blocks(model, state.position, blocks, count, w.force, w.threads);
  // (1.21): the particles that update at this tick take their elastic force times the ticks
  // since their last update; the others none (their sums are partial).
  const uint8_t* interval = s.interval.data();
  const uint8_t* phase = s.phase.data();
  int64_t* last = state.elastic_update_tick.data();
  double* f = w.force.data();
  size_t near = 0;
  for (int i = 0; i < n; ++i) {
    bool update = (p & (interval[i] - 1)) == phase[i];
    if (near < w.subcycle_near.size() && w.subcycle_near[near] == i) update = true, ++near;
    double factor = 0.0;
    if (update) {
      factor = static_cast<double>(tick - last[i]);
      last[i] = tick;
    }
    f[3 * i] *= factor;
    f[3 * i + 1] *= factor;
    f[3 * i + 2] *= factor;
  }
  add_contact_forces(state, w.force);
  MotionSums sums;
  const SymplecticEulerUpdate update{state.position.data(), state.velocity.data(), opt.integrator.dt, &sums};
  for_each_acceleration(model, opt, w.force.data(), state.velocity.data(), update, w.threads);
  sums.write(state.out);
  tool_free_motion(model, opt, state);
}

namespace {

// 1 for a free particle, 0 for a fixed one (inverse mass 0), per coordinate.
inline double free_flag(double inverse_mass) { return inverse_mass != 0.0 ? 1.0 : 0.0; }
inline Lanes free_flag(const Lanes& inverse_mass) {
  return -__builtin_convertvector(inverse_mass != 0.0, Lanes);  // comparison lanes are -1 / 0
}

// A sum over coordinates, four at a time or one at a time.
struct Sum {
  Lanes lanes = {};
  double scalar = 0.0;
  void add(const Lanes& v) { lanes += v; }
  void add(double v) { scalar += v; }
  double total() const { return (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]) + scalar; }
};

// Calls body(k, inverse mass, mass) for every coordinate k, with the particle's inverse
// mass and mass: twelve coordinates (four particles, T = Lanes) at a time, then the
// remaining particles one coordinate at a time (T = double).
template <class Body>
void for_each_coordinate(const Model& model, const Body& body) {
  const int n = model.particle_count, groups = n / kGroup;
  const double* inv_m = model.inverse_mass.data();
  const double* mass = model.mass.data();
  auto spread = [](const double* s, int q) {  // the values of particles 4p ... 4p+3 over their coordinates
    return q == 0 ? Lanes{s[0], s[0], s[0], s[1]} : q == 1 ? Lanes{s[1], s[1], s[2], s[2]} : Lanes{s[2], s[3], s[3], s[3]};
  };
  for (int p = 0; p < groups; ++p)
    for (int q = 0; q < 3; ++q)
      body(3 * kGroup * p + kGroup * q, spread(inv_m + kGroup * p, q), spread(mass + kGroup * p, q));
  for (int i = kGroup * groups; i < n; ++i)
    for (int c = 0; c < 3; ++c) body(3 * i + c, inv_m[i], mass[i]);
}

// Ap = A p = (1 + dt c) M p + dt^2 K p over the free particles (zero on fixed ones);
// returns p . Ap.
double apply_step_operator(const Model& model, const Options& opt, State& state, const Points& p, Points& Ap) {
  const double dt = opt.integrator.dt;
  const double mass_factor = 1.0 + dt * opt.integrator.damping;
  elastic_force_differential(model, state.work, p, Ap);  // -K p
  const double* P = p.data();
  double* AP = Ap.data();
  Sum p_Ap;
  for_each_coordinate(model, [&](int k, auto inv_m, auto mass) {
    using T = decltype(inv_m);
    const T p_k = load<T>(P + k);
    const T Ap_k = free_flag(inv_m) * (mass_factor * mass * p_k - dt * dt * load<T>(AP + k));
    store(AP + k, Ap_k);
    p_Ap.add(p_k * Ap_k);
  });
  return p_Ap.total();
}

}  // namespace

ImplicitEulerOperator::ImplicitEulerOperator(const Model& model, const Options& opt, State& state)
    : model_(model), opt_(opt), state_(state) {}

void ImplicitEulerOperator::apply(const Points& p, Points& Ap) { apply_step_operator(model_, opt_, state_, p, Ap); }

int ImplicitEulerOperator::conjugate_gradient(const Points& b, Points& x, double residual_norm) {
  // Preconditioned CG with the Jacobi preconditioner of the mass part, z = r / ((1 + dt c) m),
  // in three passes per iteration: A p (with p . A p), then x, r and r . r, r . z, then p.
  Workspace& w = state_.work;
  const double dt = opt_.integrator.dt;
  const double inv_mass_factor = 1.0 / (1.0 + dt * opt_.integrator.damping);
  const double* B = b.data();
  double* X = x.data();
  double* R = w.cg_r.data();
  double* P = w.cg_p.data();
  const double* AP = w.cg_Ap.data();
  // x = 0, r = b over the free particles, p = z.
  Sum r_r, r_z;
  for_each_coordinate(model_, [&](int k, auto inv_m, auto) {
    using T = decltype(inv_m);
    const T r = free_flag(inv_m) * load<T>(B + k);
    const T z = (inv_m * inv_mass_factor) * r;
    store(X + k, T{});
    store(R + k, r);
    store(P + k, z);
    r_r.add(r * r);
    r_z.add(r * z);
  });
  const double b_norm = std::sqrt(r_r.total());
  const double tolerance = residual_norm >= 0.0 ? residual_norm : opt_.integrator.cg_tolerance * b_norm;
  if (b_norm == 0.0 || b_norm <= tolerance) return 0;  // x = 0 is close enough
  double rz = r_z.total();
  const int max_iterations = opt_.integrator.cg_max_iterations;
  for (int it = 1; it <= max_iterations; ++it) {
    const double alpha = rz / apply_step_operator(model_, opt_, state_, w.cg_p, w.cg_Ap);
    Sum r_r_next, r_z_next;
    for_each_coordinate(model_, [&](int k, auto inv_m, auto) {
      using T = decltype(inv_m);
      store(X + k, load<T>(X + k) + alpha * load<T>(P + k));
      const T r = load<T>(R + k) - alpha * load<T>(AP + k);
      store(R + k, r);
      r_r_next.add(r * r);
      r_z_next.add((inv_m * inv_mass_factor) * r * r);
    });
    if (std::sqrt(r_r_next.total()) <= tolerance) return it;
    const double beta = r_z_next.total() / rz;
    for_each_coordinate(model_, [&](int k, auto inv_m, auto) {
      using T = decltype(inv_m);
      store(P + k, (inv_m * inv_mass_factor) * load<T>(R + k) + beta * load<T>(P + k));
    });
    rz = r_z_next.total();
  }
  return -1;
}

int ImplicitEulerOperator::solve(const Points& load, Points& out, double residual_norm) {
  return conjugate_gradient(load, out, residual_norm);
}

void free_motion_implicit_euler(const Model& model, const Options& opt, State& state) {
  const double dt = opt.integrator.dt;
  const double c = opt.integrator.damping;
  Workspace& w = state.work;
  const Vec3 g = opt.gravity;
  linearize_elastic(model, state.position, w);
  elastic_forces(model, state.position, w.force, w.threads);
  add_contact_forces(state, w.force);
  elastic_force_differential(model, w, state.velocity, w.cg_Ap);  // -K v
  for (int i = 0; i < model.particle_count; ++i) {
    const double m_i = model.mass[i];
    w.rhs.col(i) = dt * (w.force.col(i) + m_i * g - c * m_i * state.velocity.col(i)) + dt * dt * w.cg_Ap.col(i);
  }
  ImplicitEulerOperator op(model, opt, state);
  state.out.cg_iterations = op.conjugate_gradient(w.rhs, w.dv);
  state.velocity += w.dv;
  state.position += dt * state.velocity;
  tool_free_motion(model, opt, state);
}

}  // namespace palpate
