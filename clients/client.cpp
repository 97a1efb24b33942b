// palpate-client: the demo front-end of palpate-server. Usage: kUsage below
// (palpate-client --help).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <kj/async-io.h>
#include <kj/timer.h>
#include <kj/exception.h>

#include "cli/arguments.h"
#include "clients/connect.h"
#include "clients/haptic.h"
#include "core/hertz.h"
#include "core/vtk_writer.h"
#include "protocol/palpate.capnp.h"

namespace {

using palpate::wire::FrameSink;
using palpate::wire::PalpateServer;
using palpate::wire::Session;

const char* kUsage = R"(usage: palpate-client [options]
The demo front-end of palpate-server: opens a session and presses the indenter.
Real time (default): subscribes to the contact force and the indenter at --rate
frames per second, ramps the commanded force from 0 to --ramp FMAX over --seconds
(or holds each of --forces for an equal share of them) and prints a live table:
time, tick, commanded F, indentation d, contact force, the Hertz depth d_H of the
contact force (core/hertz.h) and d / d_H - 1; then the server's statistics.
--headless: opens a headless session and, for each force, steps until rest (contact
force within 0.1 % of the command, the indenter moving < 1e-6 m per 100 ticks and
slower than 1e-5 m/s, for 5 chunks of 100 ticks in a row) or --max-steps, printing
one row per force.
--haptic-rate HZ: plays a haptic device (clients/haptic.h). Opens a real-time session
with the tool free in 3-D (--set indenter.guide=free unless --set names the guide) and
subscribes to every tick; over --seconds the device follows a palpation path (from the
tool to above site A, press --depth below first touch, hold, slide to site B, lift, move
in the air to site C, press, hold, lift), one setPosition per tick, pipelined, while a
servo loop at HZ renders F = F0 + K (x - x0) from the newest frame's render model
(clipped to its valid radius, saturated at --device-force). Live table: time, segment,
device z, rendered Fz, the newest frame's render Fz and contact Fz. Then: command-to-
force latency (setPosition to the first frame whose commandSeq includes it), the
server's statistics, and the rendering error at each frame: its render force against
the previous frame's local model at its target and against the zero-order hold.
  --connect ADDR:PORT  the server (default 127.0.0.1:7420)
  --tls-ca FILE        connect over TLS, trusting the PEM certificate(s) in FILE (a server
                       started with --tls-cert); the certificate must name the host of
                       --connect, or --tls-server-name NAME
  --access-token-file FILE
                       authenticate with the token in FILE (a server started with
                       --access-token-file)
  --tls-server-name NAME
                       the name the server's certificate must carry (default: the host
                       of --connect)
  --scene NAME         a scene of the server's --scene-dir by name, e.g. hertz_cube_haptic
                       (default: the server's default scene)
  --set KEY=VALUE      override a scene field by its dotted path (repeatable), e.g.
                       --set body.distribution.per_edge=12
  --forces F1,F2,...   forces in N, held one after the other (headless: each to rest)
  --ramp FMAX          real time: ramp from 0 to FMAX N (default 0); headless without
                       --forces: FMAX/4, FMAX/2, 3 FMAX/4, FMAX (default FMAX 80 N)
  --seconds S          real time: length of the run, (0, 86400] (default 5)
  --rate HZ            real time: frames per second of the subscription, (0, 10000]
                       (default 50)
  --headless           a headless session, stepped to rest force by force
  --max-steps N        headless: most ticks per force, >= 1 (default 20000)
  --haptic-rate HZ     the haptic mode above with a servo loop at HZ, (0, 100000]
  --depth M            haptic: device depth below first touch, m, > 0 (default R/5)
  --device-stiffness K haptic: the device's largest stiffness, N/m, >= 0 (default 0: none)
  --device-damping B   haptic: the device's largest damping, N s/m, >= 0 (default 0: none)
  --device-force F     haptic: the device's largest force, N, >= 0 (default 0: none)
  --csv FILE           write every frame received (real time) or every row (headless):
                       the scalars above, then the tool's centre, the 3-D contact and
                       render forces and the local contact model (stiffness K row-major,
                       N/m; its valid radius, m; the tick K was computed at); haptic: one
                       row per servo tick: time, segment, device x y z, rendered F xyz,
                       the newest frame's tick, render force xyz and contact force xyz
  --vtk DIR            headless: ParaView files in DIR (created), one per row: the body as
                       the frame at rest has it, DIR/body_K.vtu (K = the row, from 0: the
                       surface triangles of SessionInfo over the particles, displacement,
                       its magnitude and the von Mises stress as the server computed them,
                       the contact force per particle; the tool's position and forces as
                       field data), the sphere, DIR/tool_K.vtu, and DIR/client.pvd, the
                       series of both with time = the frame's simTime (s). The steps then
                       ask for the frame fields positions, contacts, displacementMagnitude
                       and vonMises
  --vtk-surface        with --vtk: ask for the surface vertices only (FrameFields.surfaceOnly)
  --vtk-ascii          with --vtk: text .vtu files (default: base64 binary)
  --help               print this text and exit
Exit status: 0 when done; 1 when the connection fails or the server refuses (its
message, naming the field, is printed); 2 for a wrong argument.
)";

struct Args {
  std::string connect = "127.0.0.1:7420";
  std::string tls_ca, tls_server_name, access_token_file;
  std::string scene;  // empty: the server's default scene
  std::vector<std::string> overrides;
  std::vector<double> forces;
  double ramp = 0.0;  // > 0: ramp to this force
  double seconds = 5.0;
  double rate = 50.0;
  bool headless = false;
  long max_steps = 20000;
  std::string csv;
  std::string vtk;  // --vtk DIR
  bool vtk_surface = false, vtk_ascii = false;
  palpate::haptic::DeviceFlags haptic;  // haptic_rate > 0: the haptic mode
};

Args parse_args(int argc, char** argv) {
  Args a;
  palpate::cli::parse_or_exit(argc, argv, "palpate-client", kUsage, [&](palpate::cli::Arguments& args) {
    const std::string& flag = args.flag();
    if (flag == "--connect") a.connect = args.value();
    else if (flag == "--tls-ca") a.tls_ca = args.value();
    else if (flag == "--tls-server-name") a.tls_server_name = args.value();
    else if (flag == "--access-token-file") a.access_token_file = args.value();
    else if (flag == "--scene") a.scene = args.value();
    else if (flag == "--set") {
      const std::string assignment = args.value();
      palpate::cli::scene_override(assignment);  // KEY=VALUE; the server validates the rest
      a.overrides.push_back(assignment);
    } else if (flag == "--forces") a.forces = palpate::cli::number_list(args.value(), flag);
    else if (flag == "--ramp") a.ramp = args.number();
    else if (flag == "--seconds") {
      a.seconds = args.number();
      if (!(a.seconds > 0 && a.seconds <= 86400)) throw std::invalid_argument("--seconds: must be in (0, 86400]");
    } else if (flag == "--rate") {
      a.rate = args.number();
      if (!(a.rate > 0 && a.rate <= 10000)) throw std::invalid_argument("--rate: must be in (0, 10000]");
    } else if (flag == "--headless") a.headless = true;
    else if (flag == "--max-steps") a.max_steps = static_cast<long>(args.integer(1, 1000000000));
    else if (flag == "--csv") a.csv = args.value();
    else if (flag == "--vtk") a.vtk = args.value();
    else if (flag == "--vtk-surface") a.vtk_surface = true;
    else if (flag == "--vtk-ascii") a.vtk_ascii = true;
    else if (palpate::haptic::parse_device_flag(args, a.haptic)) {
    } else return false;
    return true;
  });
  if (a.haptic.haptic_rate > 0 && a.headless)
    palpate::cli::usage_error("palpate-client", "--haptic-rate: needs a real-time session, not --headless", kUsage);
  if (!a.vtk.empty() && !a.headless)
    palpate::cli::usage_error("palpate-client", "--vtk: writes the rows of --headless (add --headless)", kUsage);
  if ((a.vtk_surface || a.vtk_ascii) && a.vtk.empty())
    palpate::cli::usage_error("palpate-client", "--vtk-surface, --vtk-ascii: only with --vtk DIR", kUsage);
  return a;
}

struct Row {
  double time = 0, command = 0, indentation = 0, contact = 0;
  int64_t tick = 0;
  // The 3-D tool (Frame.indenterPosition, toolContactForce, renderForce) and the local
  // contact model (Frame.contactModel: stiffness row-major, N/m; valid radius, m).
  double tool[3] = {0, 0, 0}, contact_vector[3] = {0, 0, 0}, render[3] = {0, 0, 0};
  double stiffness[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  double valid_radius = 0;
  int64_t stiffness_tick = -1;
};

// The frame's fields of a Row.
Row row_of(palpate::wire::Frame::Reader f) {
  Row r;
  r.tick = f.getTick();
  r.command = f.getForceCommand();
  r.indentation = f.getIndentation();
  r.contact = f.getIndenterContactForce();
  auto put = [](double* out, palpate::wire::Vec3::Reader v) {
    out[0] = v.getX();
    out[1] = v.getY();
    out[2] = v.getZ();
  };
  put(r.tool, f.getIndenterPosition());
  put(r.contact_vector, f.getToolContactForce());
  put(r.render, f.getRenderForce());
  auto model = f.getContactModel();
  auto k = model.getStiffness();
  for (unsigned i = 0; i < 9 && i < k.size(); ++i) r.stiffness[i] = k[i];
  r.valid_radius = model.getValidRadius();
  r.stiffness_tick = model.getStiffnessTick();
  return r;
}

struct Hertz {
  double radius = 0.5, e_star = 1.0;
  double depth(double f) const { return f > 0 ? palpate::hertz::depth(f, radius, e_star) : 0.0; }
};

void print_header() {
  std::printf("%9s %9s %10s %11s %11s %11s %9s\n", "time[s]", "tick", "F_cmd[N]", "d[m]", "F_contact[N]", "d_Hertz[m]",
              "d/d_H-1");
}

void print_row(const Row& r, const Hertz& h) {
  const double dh = h.depth(r.contact);
  char diff[32] = "-";
  if (dh > 1e-9) std::snprintf(diff, sizeof diff, "%+.1f%%", 100.0 * (r.indentation / dh - 1.0));
  std::printf("%9.3f %9lld %10.3f %11.5f %11.3f %11.5f %9s\n", r.time, static_cast<long long>(r.tick), r.command,
              r.indentation, r.contact, dh, diff);
  std::fflush(stdout);
}

// Records the frames the server streams.
class Sink final : public FrameSink::Server {
 public:
  explicit Sink(std::chrono::steady_clock::time_point start) : start_(start) {}
  std::vector<Row> rows;
  Row latest;
  bool have = false;
  bool finished = false;

 protected:
  kj::Promise<void> frame(FrameContext context) override {
    Row r = row_of(context.getParams().getFrame());
    r.time = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    latest = r;
    have = true;
    if (rows.size() < 10000000) rows.push_back(r);
    return kj::READY_NOW;
  }
  kj::Promise<void> done(DoneContext) override {
    finished = true;
    return kj::READY_NOW;
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

// The haptic mode's overrides: the tool free in 3-D unless the user set the guide.
std::vector<std::string> overrides_of(const Args& a) {
  return a.haptic.haptic_rate > 0 ? palpate::haptic::with_free_guide(a.overrides) : a.overrides;
}

void fill_open(PalpateServer::OpenSessionParams::Builder params, const Args& a, bool headless) {
  auto req = params.initRequest();
  if (!a.scene.empty()) req.getScene().setName(a.scene);
  const std::vector<std::string> overrides = overrides_of(a);
  auto o = req.initOverrides(static_cast<unsigned>(overrides.size()));
  for (unsigned k = 0; k < overrides.size(); ++k) o.set(k, overrides[k]);
  req.setHeadless(headless);
  if (a.haptic.haptic_rate > 0) palpate::haptic::set_device(req, a.haptic.device_stiffness, a.haptic.device_damping, a.haptic.device_force);
}

void write_csv(const std::string& path, const std::vector<Row>& rows, const Hertz& h) {
  std::ofstream out(path);
  if (!out) {
    std::fprintf(stderr, "palpate-client: cannot write %s\n", path.c_str());
    return;
  }
  out << "time_s,tick,force_command_n,indentation_m,contact_force_n,hertz_depth_m,"
         "tool_x_m,tool_y_m,tool_z_m,contact_fx_n,contact_fy_n,contact_fz_n,render_fx_n,render_fy_n,render_fz_n,"
         "k_xx_n_per_m,k_xy_n_per_m,k_xz_n_per_m,k_yx_n_per_m,k_yy_n_per_m,k_yz_n_per_m,k_zx_n_per_m,k_zy_n_per_m,"
         "k_zz_n_per_m,valid_radius_m,stiffness_tick\n";
  out.precision(std::numeric_limits<double>::max_digits10);  // doubles round-trip exactly
  for (const Row& r : rows) {
    out << r.time << ',' << r.tick << ',' << r.command << ',' << r.indentation << ',' << r.contact << ','
        << h.depth(r.contact);
    for (double v : r.tool) out << ',' << v;
    for (double v : r.contact_vector) out << ',' << v;
    for (double v : r.render) out << ',' << v;
    for (double v : r.stiffness) out << ',' << v;
    out << ',' << r.valid_radius << ',' << r.stiffness_tick << '\n';
  }
}

int run_realtime(const Args& a, Session::Client session, const Hertz& h, kj::WaitScope& ws, kj::Timer& timer) {
  const auto start = std::chrono::steady_clock::now();
  auto sink_owner = kj::heap<Sink>(start);
  Sink& sink = *sink_owner;
  auto sub = session.subscribeRequest();
  sub.setSink(kj::mv(sink_owner));
  sub.getOptions().setRateHz(a.rate);
  auto subscription = sub.send().wait(ws).getSubscription();

  auto command_at = [&](double t) {
    if (!a.forces.empty()) {
      const size_t k = std::min(a.forces.size() - 1, static_cast<size_t>(t / a.seconds * a.forces.size()));
      return a.forces[k];
    }
    return a.ramp * std::min(1.0, t / a.seconds);
  };
  print_header();
  double last_print = -1.0, last_command = NAN;
  for (;;) {
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (t >= a.seconds) break;
    const double f = command_at(t);
    if (f != last_command) {
      auto req = session.setForceRequest();
      req.setNewtons(f);
      req.send().wait(ws);
      last_command = f;
    }
    if (sink.have && t - last_print >= 0.25) {
      print_row(sink.latest, h);
      last_print = t;
    }
    timer.afterDelay(20 * kj::MILLISECONDS).wait(ws);
  }
  if (sink.have) print_row(sink.latest, h);

  auto stats_response = session.statsRequest().send().wait(ws);

  auto stats = stats_response.getStats();
  std::printf("\nserver: %.1f Hz achieved (target %.0f Hz), %lld ticks; step p50 %.0f us, p99 %.0f us, max %.0f us\n",
              stats.getAchievedRateHz(), stats.getTargetRateHz(), static_cast<long long>(stats.getTicks()),
              stats.getStepUs().getP50(), stats.getStepUs().getP99(), stats.getStepUs().getMax());
  std::printf("        tick lateness p50 %.0f us, p99 %.0f us, max %.0f us; deadline misses %llu (%.2f %%), "
              "blow-ups %u%s\n",
              stats.getLatenessUs().getP50(), stats.getLatenessUs().getP99(), stats.getLatenessUs().getMax(),
              static_cast<unsigned long long>(stats.getDeadlineMisses()),
              stats.getTicks() > 0 ? 100.0 * stats.getDeadlineMisses() / stats.getTicks() : 0.0, stats.getBlowUps(),
              stats.getRealtimePriority() ? ", SCHED_FIFO" : "");
  for (auto s : stats.getSubscribers())
    std::printf("        subscriber %u at %.0f Hz: %llu frames sent, %llu dropped\n", s.getId(), s.getRateHz(),
                static_cast<unsigned long long>(s.getSent()), static_cast<unsigned long long>(s.getDropped()));
  std::printf("client: %zu frames received in %.1f s\n", sink.rows.size(), a.seconds);
  if (!a.csv.empty()) write_csv(a.csv, sink.rows, h);
  return 0;
}

// One row per servo tick of the haptic mode.
void write_haptic_csv(const std::string& path, const palpate::haptic::Result& r) {
  std::ofstream out(path);
  if (!out) {
    std::fprintf(stderr, "palpate-client: cannot write %s\n", path.c_str());
    return;
  }
  out << "time_s,segment,device_x_m,device_y_m,device_z_m,rendered_fx_n,rendered_fy_n,rendered_fz_n,frame_tick,"
         "frame_render_fx_n,frame_render_fy_n,frame_render_fz_n,frame_contact_fx_n,frame_contact_fy_n,"
         "frame_contact_fz_n\n";
  out.precision(9);
  for (const auto& s : r.servo) {
    out << s.t << ',' << r.segments[s.segment].label;
    for (double v : s.device) out << ',' << v;
    for (double v : s.rendered) out << ',' << v;
    out << ',' << s.frame_tick;
    for (double v : s.frame_force) out << ',' << v;
    for (double v : s.contact_force) out << ',' << v;
    out << '\n';
  }
}

int run_haptic(const Args& a, Session::Client session, palpate::wire::SessionInfo::Reader info, kj::WaitScope& ws) {
  palpate::haptic::Config config;
  config.servo_hz = a.haptic.haptic_rate;
  config.seconds = a.seconds;
  config.depth = a.haptic.depth;
  config.record_servo = !a.csv.empty();
  std::printf("haptic: servo loop at %.0f Hz, one setPosition per tick (%.0f Hz); coupling %.0f N/m, %.1f N s/m; "
              "device limits %g N/m, %g N s/m, %g N (0 = none)\n",
              a.haptic.haptic_rate, info.getRateHz(), info.getCoupling().getStiffness(), info.getCoupling().getDamping(),
              info.getDevice().getMaxStiffness(), info.getDevice().getMaxDamping(), info.getDevice().getMaxForce());
  std::printf("%8s %-11s %11s %12s %12s %12s\n", "time[s]", "segment", "device z[m]", "rendered Fz", "frame Fz[N]",
              "contact Fz");
  auto live = [](const palpate::haptic::ServoSample& s, const char* segment) {
    std::printf("%8.3f %-11s %11.5f %12.3f %12.3f %12.3f\n", s.t, segment, s.device[2], s.rendered[2],
                s.frame_force[2], s.contact_force[2]);
    std::fflush(stdout);
  };
  const palpate::haptic::Result r = palpate::haptic::run_palpation(session, info, ws, config, live);
  std::printf("\n");
  palpate::haptic::print_report(stdout, r);
  if (!a.csv.empty()) write_haptic_csv(a.csv, r);
  return 0;
}

// What a .vtu of the body needs from SessionInfo.
struct Body {
  std::vector<double> rest;              // 3 n, m
  std::vector<uint32_t> triangles;       // 3 per triangle, particle indices
  std::vector<uint32_t> surface;         // SessionInfo.surfaceVertices, ascending
  double radius = 0;                     // the tool's, m
};

Body body_of(palpate::wire::SessionInfo::Reader info) {
  Body b;
  for (float v : info.getRestPositions()) b.rest.push_back(v);
  for (uint32_t t : info.getSurfaceTriangles()) b.triangles.push_back(t);
  for (uint32_t i : info.getSurfaceVertices()) b.surface.push_back(i);
  b.radius = info.getRadius();
  return b;
}

// The frame's body and tool as DIR/body_K.vtu, DIR/tool_K.vtu (core/vtk_writer.h); appends
// their collection entries. The frame's per-particle lists are all particles, or (surfaceOnly)
// the surface vertices in SessionInfo.surfaceVertices order.
void write_frame_vtk(const Args& a, const Body& body, palpate::wire::Frame::Reader f, size_t k,
                     std::vector<palpate::vtk::CollectionEntry>& series) {
  namespace vtk = palpate::vtk;
  const auto positions = f.getPositions();
  const size_t n = body.rest.size() / 3;
  const bool surface = a.vtk_surface;
  const size_t points = surface ? body.surface.size() : n;
  if (positions.size() != 3 * points || f.getDisplacementMagnitude().size() != points ||
      f.getVonMises().size() != points)
    throw std::runtime_error("--vtk: the frame of tick " + std::to_string(f.getTick()) + " has " +
                             std::to_string(positions.size() / 3) + " positions, " +
                             std::to_string(f.getDisplacementMagnitude().size()) + " displacements and " +
                             std::to_string(f.getVonMises().size()) + " von Mises values for " +
                             std::to_string(points) + " points");
  // particle -> point of this grid
  std::vector<int64_t> point_of(n, -1);
  for (size_t p = 0; p < points; ++p) point_of[surface ? body.surface[p] : p] = static_cast<int64_t>(p);
  vtk::UnstructuredGrid g;
  g.points.reserve(positions.size());
  for (float x : positions) g.points.push_back(x);
  if (!body.triangles.empty()) {
    std::vector<int64_t> c;
    c.reserve(body.triangles.size());
    for (uint32_t i : body.triangles) c.push_back(point_of.at(i));
    vtk::add_cells(g, vtk::CellType::triangle, c);
  } else {
    vtk::add_vertex_cells(g);
  }
  vtk::DataArray displacement{"displacement", 3, {}}, magnitude{"displacement_magnitude", 1, {}},
      von_mises{"von_mises", 1, {}}, contact{"contact_force", 3, std::vector<double>(3 * points, 0.0)};
  for (size_t p = 0; p < points; ++p) {
    const size_t i = surface ? body.surface[p] : p;
    for (int c = 0; c < 3; ++c) displacement.values.push_back(positions[3 * p + c] - body.rest[3 * i + c]);
    magnitude.values.push_back(f.getDisplacementMagnitude()[p]);
    von_mises.values.push_back(f.getVonMises()[p]);
  }
  const auto nodes = f.getContactNodes();
  const auto forces = f.getContactForces();
  for (unsigned c = 0; c < nodes.size(); ++c) {
    const int64_t p = nodes[c] < n ? point_of[nodes[c]] : -1;
    if (p < 0) continue;  // a contact off the surface: not a point of a surface-only grid
    for (int d = 0; d < 3; ++d) contact.values[3 * static_cast<size_t>(p) + d] = forces[3 * c + d];
  }
  g.point_data = {std::move(displacement), std::move(magnitude), std::move(von_mises), std::move(contact)};
  auto vec = [](palpate::wire::Vec3::Reader v) { return std::vector<double>{v.getX(), v.getY(), v.getZ()}; };
  g.field_data = {{"time", 1, {f.getSimTime()}},
                  {"tick", 1, {static_cast<double>(f.getTick())}},
                  {"tool_position", 3, vec(f.getIndenterPosition())},
                  {"tool_contact_force", 3, vec(f.getToolContactForce())},
                  {"force_command", 3, vec(f.getForceVector())}};
  const auto c = f.getIndenterPosition();
  vtk::UnstructuredGrid tool = vtk::sphere_surface(palpate::Vec3(c.getX(), c.getY(), c.getZ()), body.radius);
  tool.field_data = g.field_data;
  const vtk::Encoding encoding = a.vtk_ascii ? vtk::Encoding::ascii : vtk::Encoding::binary;
  const std::filesystem::path dir(a.vtk);
  const std::string name = std::to_string(k);
  vtk::write_vtu(dir / ("body_" + name + ".vtu"), g, encoding);
  vtk::write_vtu(dir / ("tool_" + name + ".vtu"), tool, encoding);
  series.push_back({f.getSimTime(), 0, "body_" + name + ".vtu"});
  series.push_back({f.getSimTime(), 1, "tool_" + name + ".vtu"});
  vtk::write_pvd(dir / "client.pvd", series);
}

int run_headless(const Args& a, Session::Client session, palpate::wire::SessionInfo::Reader info, const Hertz& h,
                 double dt, kj::WaitScope& ws) {
  const Body body = a.vtk.empty() ? Body{} : body_of(info);
  std::vector<palpate::vtk::CollectionEntry> series;
  if (!a.vtk.empty()) std::filesystem::create_directories(a.vtk);
  std::vector<double> forces = a.forces;
  if (forces.empty()) {
    const double top = a.ramp > 0 ? a.ramp : 80.0;
    for (int k = 1; k <= 4; ++k) forces.push_back(top * k / 4.0);
  }
  print_header();
  std::vector<Row> rows;
  const auto start = std::chrono::steady_clock::now();
  for (double f : forces) {
    auto req = session.setForceRequest();
    req.setNewtons(f);
    req.send().wait(ws);
    Row r;
    double previous_d = NAN;
    long steps = 0;
    std::optional<capnp::Response<Session::StepResults>> last_frame;
    int quiet = 0;
    constexpr unsigned kChunk = 100;
    while (steps < a.max_steps) {
      auto step = session.stepRequest();
      step.setN(kChunk);
      if (!a.vtk.empty()) {  // every chunk: the client does not know which one ends at rest
        auto fields = step.initFields();
        fields.setPositions(true);
        fields.setContacts(true);
        fields.setDisplacementMagnitude(true);
        fields.setVonMises(true);
        fields.setSurfaceOnly(a.vtk_surface);
      }
      last_frame.emplace(step.send().wait(ws));
      auto frame = last_frame->getFrame();
      steps += kChunk;
      r = row_of(frame);
      r.time = frame.getSimTime();
      const bool balanced = std::abs(r.contact - f) <= 1e-3 * std::max(std::abs(f), 1e-9);
      const bool still = std::abs(r.indentation - previous_d) <= 1e-6 && std::abs(frame.getIndenterVelocity()) <= 1e-5;
      previous_d = r.indentation;
      quiet = balanced && still ? quiet + 1 : 0;
      if (quiet >= 5) break;  // 0.5 s at dt = 1 ms: not just a turning point of an oscillation
    }
    print_row(r, h);
    if (!a.vtk.empty() && last_frame) write_frame_vtk(a, body, last_frame->getFrame(), rows.size(), series);
    rows.push_back(r);
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  auto stats_response = session.statsRequest().send().wait(ws);
  auto stats = stats_response.getStats();
  std::printf("\nheadless: %lld ticks (%.1f s simulated at dt %.3g s) in %.2f s wall, %.0f ticks/s; step p50 %.0f us, "
              "p99 %.0f us; blow-ups %u\n",
              static_cast<long long>(stats.getTicks()), stats.getTicks() * dt, dt, wall, stats.getAchievedRateHz(),
              stats.getStepUs().getP50(), stats.getStepUs().getP99(), stats.getBlowUps());
  if (!a.csv.empty()) write_csv(a.csv, rows, h);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const Args a = parse_args(argc, argv);
  try {
    palpate::client::ConnectOptions connect;
    connect.address = a.connect;
    connect.tls_ca_file = a.tls_ca;
    connect.tls_server_name = a.tls_server_name;
    if (!a.access_token_file.empty()) connect.access_token = palpate::client::read_token_file(a.access_token_file);
    palpate::client::ServerConnection client(connect);
    auto& ws = client.wait_scope();
    auto server = client.server();
    auto version = server.versionRequest().send().wait(ws);
    if (version.getProtocolVersion() != palpate::wire::PROTOCOL_VERSION)
      std::fprintf(stderr, "palpate-client: warning: server speaks protocol %u, this client %u\n",
                   version.getProtocolVersion(), palpate::wire::PROTOCOL_VERSION);
    auto open = server.openSessionRequest();
    fill_open(open, a, a.headless);
    auto opened = open.send().wait(ws);
    auto info = opened.getInfo();
    Hertz h;
    h.radius = info.getRadius();
    h.e_star = palpate::hertz::effective_modulus(info.getYoungModulus(), info.getPoissonRatio());
    std::printf("scene %s: %u particles, dt %.3g s, %s (%.0f Hz), force limit %.0f N, model built in %.2f s\n",
                info.getSceneName().cStr(), info.getParticleCount(), info.getDt(),
                info.getHeadless() ? "headless" : "real time", info.getRateHz(), info.getForceLimit(),
                info.getBuildSeconds());
    if (a.headless) return run_headless(a, opened.getSession(), info, h, info.getDt(), ws);
    if (a.haptic.haptic_rate > 0) return run_haptic(a, opened.getSession(), info, ws);
    return run_realtime(a, opened.getSession(), h, ws, client.timer());
  } catch (const kj::Exception& e) {
    std::fprintf(stderr, "palpate-client: %s\n", e.getDescription().cStr());
    return 1;
  } catch (const std::exception& e) {  // the haptic loop: no frame, a session it cannot palpate
    std::fprintf(stderr, "palpate-client: %s\n", e.what());
    return 1;
  }
}
