# palpate wire protocol: a meshless soft-tissue simulation pressed by a rigid
# sphere, served in real time (fixed-rate loop) or headless (stepped on demand).
#
# Conventions: SI units (m, kg, s, N, Pa), world frame (z up; the body's top face
# is its largest z). The tool (the "indenter", a rigid sphere) has three
# translational degrees of freedom; the scene's indenter.guide may hold it on a
# vertical line. It is driven either by a force (setForce: a scalar pressing it
# down, -z; setForceVector: any direction) or by a device position through a
# virtual coupling (setPosition). A "tick" is one simulation step of the scene's
# dt. Errors (bad scene, refused command) come back as RPC exceptions whose
# description names the field and the reason, e.g.
#   "<rpc scene>: /material/poisson_ratio: must be a number in (-1, 0.5), got 0.7".
#
# Versioning: `protocolVersion` below, returned by PalpateServer.version(). It changes
# whenever a change is not backwards compatible (renumbered or retyped fields,
# changed defaults, changed meaning); additions with new ordinals keep it.
@0x84615ea29ce2782e;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("palpate::wire");
using Json = import "/capnp/compat/json.capnp";

const protocolVersion :UInt32 = 3;
# 2: the 3-D tool (position and force-vector commands, 3-D frames, the local
# contact model, device limits, Session.close, Subscription.cancel) and scene
# defaults that scale with the scene (changed defaults are not wire compatible).
# 3: sessions belong to their opener (docs/protocol.md, "Security model"):
# openSession returns a control token, attach() without it gives a read-only view
# (commands refused), session ids are random and grant only viewing, only control
# references keep a session alive, PalpateServer.authenticate for servers started
# with an access token, and limits per connection and per session.

# ---------------------------------------------------------------------------
# Scene: the same content as a JSON scene file (docs/scene-format.md), with the
# file's snake_case names as $Json.name. The server turns it into JSON (only the
# fields that differ from the defaults below, and the lists that are set) and
# validates it with the file validator, so a wire scene and a file behave the
# same and errors name the JSON pointer of the field. Every default below equals
# the file format's default; a null list means "absent" (the file default). A
# numeric field's comment writes its range before the first ';'. Defaults and
# ranges are checked against the file reader and docs/scene-format.md by
# tests/scene_schema_test.cpp.

enum DistributionType {
  grid @0;
  jitteredGrid @1 $Json.name("jittered_grid");
  nodeFile @2 $Json.name("node_file");
  gradedGrid @3 $Json.name("graded_grid");   # geometric lattice graded toward a focus
  mesh @4;                                   # vertices of a tetrahedral mesh file (Distribution.file)
}
enum SupportRule {
  meanDistance @0 $Json.name("mean_distance");  # h = alpha * mean distance to the k neighbours
  kthDistance @1 $Json.name("kth_distance");    # h = alpha * distance to the k-th neighbour
}
enum IntegrationRule {
  nodal @0;       # MLS gradients as they are
  consistent @1;  # corrected to satisfy the integration constraint (patch test on any cloud)
}
enum VolumeRule {
  kernel @0;   # (A-2, A-3) kernel sums
  lattice @1;  # lattice cell volumes
  mesh @2;     # a quarter of each incident tetrahedron (required by, and only for, mesh clouds)
}
enum ToolGuide {
  vertical @0;
  free @1;
}
enum IntegratorType {
  rk4 @0;
  symplecticEuler @1 $Json.name("symplectic_euler");
  implicitEuler @2 $Json.name("implicit_euler");
}
enum HexFormulation {
  linear @0;
  corotational @1;
  neoHookean @2 $Json.name("neo_hookean");
}
enum HexVolumetricIntegration {
  full @0;                       # 2x2x2 Gauss points like the rest of K_e
  reduced @1;                    # the lambda part at the centre (selective reduced integration)
}
enum Face {
  bottom @0;                     # z = min.z
  top @1;                        # z = max.z
  xMin @2 $Json.name("x_min");
  xMax @3 $Json.name("x_max");
  yMin @4 $Json.name("y_min");
  yMax @5 $Json.name("y_max");
  sides @6;                      # x_min, x_max, y_min, y_max
}

struct Box {
  min @0 :List(Float64);  # [x, y, z], m; null = [-1, -1, -2]
  max @1 :List(Float64);  # [x, y, z], m; null = [1, 1, 0]
}
struct Distribution {
  type @0 :DistributionType = grid;
  perEdge @1 :Int32 = 18 $Json.name("per_edge");       # [2, 200], used when spacing == 0
  spacing @2 :Float64 = 0;                             # m, >= 0; > 0 chooses the lattice by spacing
  jitter @3 :Float64 = 0.3;                            # [0, 0.5), fraction of the spacing
  seed @4 :UInt32 = 1;                                 # jittered_grid (the wire carries 32 bits)
  nodeFile @5 :Text $Json.name("node_file");           # path on the server, relative to --scene-dir
  firstSpacing @6 :Float64 = 0 $Json.name("first_spacing");  # m, >= 0; graded_grid: the spacing at the focus; 0 = derived
  focus @7 :List(Float64);                             # graded_grid: [x, y, z], m; null = top face under the indenter
  file @8 :Text;                                       # mesh: .msh (gmsh) or .node (+ .ele, TetGen) on the server,
                                                       # relative to --scene-dir
}
struct Body {
  box @0 :Box;
  distribution @1 :Distribution;
}
struct Mls {
  neighbors @0 :Int32 = 16;                                   # k, [4, 64]
  supportFactor @1 :Float64 = 1.0 $Json.name("support_factor"); # alpha, (0, 10]
  volumes @2 :VolumeRule = kernel;
  hourglass @3 :Float64 = 0;                                  # [0, 100], 0 = off
  regularization @4 :Float64 = 1e-6;                          # [0, 1)
  supportRule @5 :SupportRule = meanDistance $Json.name("support_rule");
  integration @6 :IntegrationRule = nodal;
  maxNeighbors @7 :Int32 = 0 $Json.name("max_neighbors");    # 0 or [neighbors, 128]; 0 = k for every particle
  massFloor @8 :Float64 = 0 $Json.name("mass_floor");         # [0, 1]: m_i >= this * its neighbours' mean mass; 0 = off
}
struct HexFem {
  formulation @0 :HexFormulation = linear;
  volumetricIntegration @1 :HexVolumetricIntegration = full $Json.name("volumetric_integration");
}
struct Material {
  youngModulus @0 :Float64 = 1e4 $Json.name("young_modulus");       # Pa, (0, 1e12]
  poissonRatio @1 :Float64 = 0.3 $Json.name("poisson_ratio");       # (-1, 0.5)
  density @2 :Float64 = 1000;                                        # kg/m^3, (0, 1e5]
  volumeStiffness @3 :Float64 = 0 $Json.name("volume_stiffness");   # Pa, [0, 1e12]
  law @4 :MaterialLaw = stvk;                                        # the MLS strain-energy density
  inclusions @5 :List(Inclusion);                                    # null = homogeneous
}
# A region of another material (docs/scene-format.md, material.inclusions): one shape,
# and its material. Sent to the reader as the file's {"sphere": {...}, "young_modulus": ...}.
struct Inclusion {
  union {
    sphere @0 :Sphere;
    box @1 :Box;                 # both corners required
    group @2 :Text;              # a physical volume group of the mesh body, by name
  }
  youngModulus @3 :Float64 $Json.name("young_modulus");  # Pa, (0, 1e12]; required
  poissonRatio @4 :Float64 $Json.name("poisson_ratio");  # (-1, 0.5); required
  density @5 :Float64;           # kg/m^3, (0, 1e5]; 0 = the matrix's material.density
}
struct Sphere {
  center @0 :List(Float64);      # [x, y, z], m; required
  radius @1 :Float64;            # m, > 0
}
struct Plane {
  point @0 :List(Float64);       # [x, y, z], m, a point of the plane; required
  normal @1 :List(Float64);      # [x, y, z], any length > 0; required
  tolerance @2 :Float64 = 1e-9;  # m, [0, 1e3]: the nodes this close to the plane are fixed
}
# A fixed region besides the faces (docs/scene-format.md, "fixed"): the nodes of a mesh
# group or inside a geometric selector. The file has one list, `fixed`, of face names and
# region objects; on the wire the regions are Scene.fixedRegions, and the reader sees
# `fixed` = the faces followed by the regions (messages number them so).
struct FixedRegion {
  union {
    group @0 :Text;              # a physical surface group of the mesh body (its nodes)
    plane @1 :Plane;
    box @2 :Box;                 # closed; both corners required
    sphere @3 :Sphere;           # closed
  }
}
enum MaterialLaw {
  stvk @0;                       # St Venant-Kirchhoff (the paper's)
  corotational @1;               # linear law of the Biot strain, rotated
  linear @2;                     # small strain (verification against the linear hex FEM)
  neoHookean @3 $Json.name("neo_hookean");  # compressible neo-Hookean
}
struct Indenter {
  radius @0 :Float64 = 0.5;        # m, (0, 1000]
  mass @1 :Float64 = 1.0;          # kg, (0, 1e6]
  position @2 :List(Float64);      # [x, y, z] m; null = centred over the top face, just touching
  force @3 :Float64 = 0;           # N, [-1e9, 1e9]; initial command, pressing down when positive
  workspaceMin @4 :List(Float64) $Json.name("workspace_min");  # [x, y, z] m; null = the body's box grown by 2 R
  workspaceMax @5 :List(Float64) $Json.name("workspace_max");  # [x, y, z] m; null = the body's box grown by 2 R
  guide @6 :ToolGuide = vertical;
}
struct Contact {
  tolerance @0 :Float64 = 0;                                 # m, [0, 1]; 0 = 2e-6 R
  maxIterations @1 :Int32 = 200 $Json.name("max_iterations"); # [1, 1e6]
}
struct Integrator {
  type @0 :IntegratorType = rk4;
  dt @1 :Float64 = 0.001;                                         # s, (0, 1]
  damping @2 :Float64 = 0;                                        # 1/s, [0, 1e6]
  cgTolerance @3 :Float64 = 1e-8 $Json.name("cg_tolerance");      # (0, 1)
  cgMaxIterations @4 :Int32 = 1000 $Json.name("cg_max_iterations"); # [1, 1e6]
  allowUnstableDt @5 :Bool = false $Json.name("allow_unstable_dt");  # skip the stable-envelope check
  threads @6 :Int32 = 1;                                          # [1, 64], threads of the force loops
  maxInterval @7 :Int32 = 1 $Json.name("max_interval");           # [1, 64], ticks, a power of two: subcycling (1 = off)
}
struct Health {                  # per-step health checks (core/health.h, docs/scene-format.md)
  enabled @0 :Bool = true;
  energyFactor @1 :Float64 = 10 $Json.name("energy_factor");                # [1, inf)
  maxIndenterSpeed @2 :Float64 = 0 $Json.name("max_indenter_speed");        # m/s, >= 0; 0 = one spacing per step
  maxPenetration @3 :Float64 = 0 $Json.name("max_penetration");             # m, >= 0; 0 = tolerance + 5 % spacing
  inversionSweepTicks @4 :Int32 = 64 $Json.name("inversion_sweep_ticks");   # [1, 1e6]
}
struct Rest {
  velocityTolerance @0 :Float64 = 0 $Json.name("velocity_tolerance");    # m/s, >= 0; 0 = 1e-5 R / window
  forceTolerance @1 :Float64 = 1e-3 $Json.name("force_tolerance");       # relative, > 0
  window @2 :Float64 = 0.05;                                             # s, > 0
  maxTime @3 :Float64 = 60 $Json.name("max_time");                        # s, (0, 1e6]
}
struct Verify {
  forces @0 :List(Float64);  # N, each in (0, 1e9]; null or empty = Hertz loads for d/R = 0.02 ... 0.2
  rest @1 :Rest;
}
struct Scene {
  name @0 :Text;                     # null = "<rpc scene>"
  model @1 :Text;                    # "mls" (null) or "hex_fem"
  body @2 :Body;
  mls @3 :Mls;
  hexFem @4 :HexFem $Json.name("hex_fem");
  material @5 :Material;
  fixed @6 :List(Face);              # null = ["bottom", "sides"]; empty = a free body
  indenter @7 :Indenter;
  contact @8 :Contact;
  integrator @9 :Integrator;
  gravity @10 :List(Float64);        # [x, y, z] m/s^2; null = [0, 0, 0]; norm <= 1000
  verify @11 :Verify;
  health @12 :Health;
  fixedRegions @13 :List(FixedRegion) $Json.name("fixed_regions");
                                     # null = none; non-empty needs `fixed` set (empty for regions only)
}

# ---------------------------------------------------------------------------
# Opening a session.

struct OpenRequest {
  scene :union {
    serverDefault @0 :Void;  # the server's --scene file
    name @1 :Text;           # a file <name>.json under the server's --scene-dir (plain name, no path)
    inlineScene @2 :Scene;   # a scene sent by the client
  }
  overrides @3 :List(Text);  # "dotted.key=value", applied before validation (like --set)
  headless @4 :Bool;         # true: not paced, advanced only by Session.step()
  rateHz @5 :Float64;        # real-time loop rate; 0 = the server's --rate. (0, 10000]
  device @6 :DeviceLimits;   # the haptic device's limits; null = none (only the scene's force limit)
  coupling @7 :Coupling;     # initial virtual coupling for setPosition; null or 0 = the session's default
  hapticRateHz @8 :Float64;  # multirate: the server renders the device's force at this rate from the newest
                             # step's local model (renderModel at the newest setPosition), between the
                             # steps of the full model at rateHz, and streams a frame per render
                             # (docs/protocol.md, "Multirate"). 0 = off (a frame per step). Real-time
                             # sessions only; [rateHz, 10000]
}

# What a haptic device can render, given at session open. The virtual coupling's
# stiffness and damping are clamped to them (a desktop device renders about
# 0.4 to 1 N/mm at 1 kHz), and renderForce is saturated at maxForce. 0 = no limit.
struct DeviceLimits {
  maxStiffness @0 :Float64;  # N/m, >= 0
  maxDamping @1 :Float64;    # N s/m, >= 0
  maxForce @2 :Float64;      # N, >= 0
}

# The virtual coupling of position commands (docs/physics.md (2.6)): a spring and
# damper from the device position to the tool's centre.
struct Coupling {
  stiffness @0 :Float64;     # k, N/m, >= 0
  damping @1 :Float64;       # b, N s/m, >= 0
}

enum ControlMode {
  force @0;      # the tool answers a force command (setForce, setForceVector)
  position @1;   # the tool follows a device position through the virtual coupling (setPosition)
}

struct SessionInfo {
  sceneName @0 :Text;
  particleCount @1 :UInt32;
  dt @2 :Float64;              # s per tick
  rateHz @3 :Float64;          # target tick rate (0 for headless)
  headless @4 :Bool;
  forceLimit @5 :Float64;      # N; setForce refuses |F| above it (see Session.setForce)
  restPositions @6 :List(Float32);  # 3 n, x y z per particle, m (the reference configuration)
  touchHeight @7 :Float64;     # z of the indenter centre when it first touches the undeformed body, m
  radius @8 :Float64;          # indenter radius, m
  youngModulus @9 :Float64;    # Pa (for the Hertz prediction on the client)
  poissonRatio @10 :Float64;
  buildSeconds @11 :Float64;   # time spent building the model
  sessionId @12 :UInt32;       # for PalpateServer.attach() from another connection
  workspaceMin @13 :Vec3;      # m, the box the tool's centre stays in (setPosition targets must be inside)
  workspaceMax @14 :Vec3;      # m
  toolMass @15 :Float64;       # kg
  guide @16 :ToolGuide;        # vertical: the tool moves along z only
  device @17 :DeviceLimits;    # as given at open (0 = no limit)
  coupling @18 :Coupling;      # the coupling in effect for setPosition (after clamping)
  surfaceTriangles @19 :List(UInt32);  # 3 per triangle, particle indices, counterclockwise seen from
                                       # outside: the undeformed boundary surface (empty: none known)
  surfaceVertices @20 :List(UInt32);   # the particles surfaceTriangles references, each once, ascending:
                                       # the order of a frame's per-particle lists with FrameFields.surfaceOnly
  referenceForces @21 :List(Float64);       # N: the stored finite-block reference of this scene (the one of
                                            # the server's --scene-dir/references whose key matches), for a
                                            # force-depth plot; empty when the server has none
  referenceIndentation @22 :List(Float64);  # m, the converged indentation at each of referenceForces
  referenceUncertainty @23 :List(Float64);  # m, its uncertainty
  hapticRateHz @24 :Float64;   # OpenRequest.hapticRateHz in effect (0: off, a frame per step)
  control @25 :Bool;           # this reference commands the session (openSession's, or attach() with the
                               # control token); false: a read-only view (subscribe, stats, status, info)
}

# ---------------------------------------------------------------------------
# Streaming.

struct Vec3 {
  x @0 :Float64;
  y @1 :Float64;
  z @2 :Float64;
}

# Which optional fields a subscription (or step()) fills. The scalar fields of
# Frame (tick, times, indenter, contact force, command) are always present.
struct FrameFields {
  positions @0 :Bool;   # Frame.positions (3 n Float32, ~70 KB for 18^3)
  contacts @1 :Bool;    # Frame.contactNodes / contactForces
  displacementMagnitude @2 :Bool;  # Frame.displacementMagnitude (n Float32)
  vonMises @3 :Bool;               # Frame.vonMises (n Float32)
  surfaceOnly @4 :Bool;  # the per-particle lists (positions, displacementMagnitude, vonMises) carry
                         # only SessionInfo.surfaceVertices, in that order (refused when it is empty)
}

# The force on a point near `origin`, linearised: F(x) = force + stiffness (x - origin),
# for |x - origin| <= validRadius (docs/protocol.md, "The local contact model").
# A haptic servo loop faster than the tick rate renders from it between frames.
struct LocalModel {
  origin @0 :Vec3;              # m
  force @1 :Vec3;               # N, at origin
  stiffness @2 :List(Float64);  # N/m, 3 x 3 row-major: stiffness[3 i + j] = dF_i / dx_j
  validRadius @3 :Float64;      # m; beyond it the contact set may change (0 = do not extrapolate)
  stiffnessTick @4 :Int64;      # the tick whose state the stiffness was computed from (<= Frame.tick)
}

struct Frame {
  tick @0 :Int64;                   # ticks since the session (re)started; resets with reset()
  simTime @1 :Float64;              # s
  publishNs @2 :Int64;              # server CLOCK_MONOTONIC when the tick finished, ns
  indenterPosition @3 :Vec3;        # m
  indenterVelocity @4 :Float64;     # m/s, z component of toolVelocity
  indenterContactForce @5 :Float64; # N, z component of toolContactForce (positive up)
  indentation @6 :Float64;          # m, travel below first touch under the tool's (x, y) (positive when pressing)
  forceCommand @7 :Float64;         # N, the pressing force in effect during this tick: -z of forceVector
  commandSeq @8 :UInt64;            # sequence number of the last command applied (0 = none)
  recoveries @9 :UInt32;            # blow-ups recovered so far in this session
  positions @10 :List(Float32);     # 3 n: x y z per particle, m (when FrameFields.positions; surfaceOnly:
                                    # 3 per SessionInfo.surfaceVertices, in that order)
  contactNodes @11 :List(UInt32);   # particles in contact (when FrameFields.contacts)
  contactForces @12 :List(Float32); # 3 per contact: force on that particle, N
  toolVelocity @13 :Vec3;           # m/s
  toolContactForce @14 :Vec3;       # N, force of the body on the tool (sum of the contact forces, negated)
  forceVector @15 :Vec3;            # N, the force command in effect (force mode; zero in position mode)
  mode @16 :ControlMode;
  target @17 :Vec3;                 # m, the device position of the last setPosition (position mode)
  renderForce @18 :Vec3;            # N, the force for the device to render: position mode: the coupling's
                                    # force on the device, saturated at DeviceLimits.maxForce; force mode:
                                    # toolContactForce
  contactModel @19 :LocalModel;     # toolContactForce as a function of the tool's centre (origin = its position)
  renderModel @20 :LocalModel;      # renderForce as a function of the device position (position mode:
                                    # origin = target, quasi-static tool; force mode: = contactModel)
  forceSaturated @21 :Bool;         # renderForce was clipped to DeviceLimits.maxForce
  displacementMagnitude @22 :List(Float32);  # m, |x - X| per particle (when FrameFields.displacementMagnitude;
                                             # surfaceOnly: per SessionInfo.surfaceVertices)
  vonMises @23 :List(Float32);      # Pa, von Mises equivalent of the particle's (node's) Cauchy stress
                                    # (core/stress.h; when FrameFields.vonMises; surfaceOnly as above)
  hapticTick @24 :Int64 = -1;       # multirate: the server's render tick that made this frame (renderForce,
                                    # target, forceSaturated and publishNs are its); -1 when multirate is off
  modelAgeNs @25 :Int64;            # multirate: publishNs minus the publish time of the step the force was
                                    # rendered from, ns (the rest of the frame is the newest step's, which
                                    # may be one newer); 0 when multirate is off
  deadlineMisses @26 :UInt64;       # the session's deadline misses so far (Stats.deadlineMisses), so that a
                                    # client sees each miss in the stream as it happens
  hapticMisses @27 :UInt64;         # multirate: the render ticks that ended after the next one's deadline
}

interface FrameSink {
  frame @0 (frame :Frame) -> stream;
  # One frame. The server sends the next only after this one's flow-control
  # go-ahead; frames in between are dropped (newest wins) and counted.
  done @1 (reason :Text);
  # No more frames follow: the subscription was cancelled, the session closed or
  # the server is shutting down (reason says which).
}

struct SubscribeOptions {
  rateHz @0 :Float64;     # maximum frames per second; 0 = every tick
  fields @1 :FrameFields;
}

interface Subscription {
  # Handle of a subscription: cancel() or releasing it unsubscribes.
  cancel @0 () -> ();
  # Ends the subscription now: no frame is sent after this call returns; the sink
  # gets done("subscription cancelled"). Idempotent.
}

# ---------------------------------------------------------------------------
# Statistics.

struct Percentiles {
  p50 @0 :Float64;
  p99 @1 :Float64;
  max @2 :Float64;
}

struct SubscriberStats {
  id @0 :UInt32;
  rateHz @1 :Float64;     # requested (0 = every tick)
  sent @2 :UInt64;        # frames sent
  dropped @3 :UInt64;     # frames due by rate but skipped because the previous one was in flight
  inFlight @4 :Bool;
}

struct Stats {
  ticks @0 :Int64;                # ticks stepped since the session started (all resets included)
  elapsedSeconds @1 :Float64;     # wall time since the loop started
  targetRateHz @2 :Float64;
  achievedRateHz @3 :Float64;     # ticks / elapsed wall time (headless: ticks per second of stepping)
  stepUs @4 :Percentiles;         # time of one core step, us
  latenessUs @5 :Percentiles;     # tick start minus its absolute deadline, us (real-time only)
  deadlineMisses @6 :UInt64;      # ticks whose work ended after the next tick's deadline
  skippedTicks @7 :UInt64;        # deadlines abandoned when the loop fell more than a period behind
  blowUps @8 :UInt32;             # non-finite states detected and recovered
  framesPublished @9 :UInt64;
  framesCoalesced @10 :UInt64;    # published frames the RPC thread never saw (a newer one replaced them)
  subscribers @11 :List(SubscriberStats);
  realtimePriority @12 :Bool;     # SCHED_FIFO granted to the loop thread
  spinMarginUs @13 :Float64;      # the loop sleeps until this long before a deadline, then spins
  stiffnessEvaluations @14 :UInt64;  # contact stiffnesses computed for the local models (docs/protocol.md)
  missesLateStart @15 :UInt64;    # of deadlineMisses: the tick started over half a period late (the host
                                  # did not run the loop in time)
  missesLongStep @16 :UInt64;     # of deadlineMisses: the tick started in time and its work overran
  pinned @17 :Bool;               # the loop runs on a core of its own (palpate-server --pin)
  watchdogYields @18 :UInt64;     # times the loop, behind its deadlines for longer than the watchdog allows,
                                  # slept a period so that the server's other threads could run
  hapticRateHz @19 :Float64;      # multirate render rate (0: off)
  hapticTicks @20 :Int64;         # render ticks since the start
  hapticMisses @21 :UInt64;       # render ticks that ended after the next one's deadline
  hapticLatenessUs @22 :Percentiles;  # render tick start minus its deadline, us
  modelAgeUs @23 :Percentiles;    # at each render tick, the age of the step it rendered from, us
  refocuses @24 :UInt64;          # a cloud that follows the tool: refocuses swapped in (docs/physics.md §7)
  refocusesDropped @25 :UInt64;   # and those dropped (a failed build or shadow, a reset or recovery)
}

enum RunState {
  starting @0;   # the model is being built
  running @1;    # real-time loop ticking
  paused @2;     # real-time loop alive, not stepping
  headless @3;   # advanced only by step()
  failed @4;     # the model could not be built (see message)
}

struct Status {
  state @0 :RunState;
  tick @1 :Int64;
  simTime @2 :Float64;
  forceCommand @3 :Float64;    # N, pressing (-z of the force command)
  blowUps @4 :UInt32;
  lastBlowUp @5 :Text;         # what was detected and how it recovered; empty if none
  lastBlowUpTick @6 :Int64;    # -1 if none
  mode @7 :ControlMode;
  closed @8 :Bool;             # Session.close() was called
}

# ---------------------------------------------------------------------------
# Interfaces.

interface Session {
  # A control reference (openSession's, or attach() with the control token) may call
  # every method; a read-only view (attach() without it) only subscribe, stats,
  # status and info: its other calls are refused with a message that says so.
  setForce @0 (newtons :Float64) -> (seq :UInt64, queuedAtTick :Int64);
  # Force mode with the force (0, 0, -newtons): N, pressing down when positive,
  # applied at the start of the next tick. Refused, leaving the state untouched,
  # when NaN, infinite or |F| > SessionInfo.forceLimit (100 x the scene's largest
  # verification force, or 100 x the Hertz force at d = R / 5 when the scene has
  # no sweep). seq appears in Frame.commandSeq once applied; queuedAtTick is the
  # newest published tick when the command was queued.

  reset @1 () -> (seq :UInt64);
  # Back to the rest state of the scene (tick 0, the scene's initial force).

  pause @2 () -> (seq :UInt64);
  resume @3 () -> (seq :UInt64);
  # Real-time sessions: stop / restart stepping (the loop keeps its deadlines).

  subscribe @4 (sink :FrameSink, options :SubscribeOptions) -> (subscription :Subscription);
  # Streams frames to sink until the returned handle is released or the
  # connection drops. Headless sessions stream the frames step() produces.
  # Refused beyond the server's --max-subscribers per session. Each subscriber
  # has at most one frame in flight (the next is sent after its flow-control
  # go-ahead; frames in between are dropped and counted), so one that never
  # reads holds one frame and its socket's send buffer, nothing more.

  step @5 (n :UInt32, fields :FrameFields) -> (frame :Frame);
  # Headless sessions only: advances exactly n ticks (n <= 10^6) and returns the
  # last frame. Deterministic: the same scene and calls give bit-identical frames.

  stats @6 () -> (stats :Stats);
  status @7 () -> (status :Status);
  info @8 () -> (info :SessionInfo);

  setForceVector @9 (force :Vec3) -> (seq :UInt64, queuedAtTick :Int64);
  # Force mode with any force on the tool (N, world frame). Refused when a
  # component is not finite or |force| > SessionInfo.forceLimit.

  setPosition @10 (position :Vec3) -> (seq :UInt64, queuedAtTick :Int64);
  # Position mode: the device is at `position` (m); the virtual coupling pulls the
  # tool toward it and Frame.renderForce is the force to render. Refused when a
  # component is not finite or the point is outside the tool workspace
  # (SessionInfo.workspaceMin/Max).

  setCoupling @11 (coupling :Coupling) -> (seq :UInt64, coupling :Coupling);
  # The coupling's stiffness and damping, clamped to the device's limits; returns
  # the values in effect. Refused when negative or not finite.

  close @12 () -> ();
  # Ends the session now: its loop stops, every subscriber gets done("session
  # closed"), and every later call on it fails. Other references (attach) see it
  # closed too. Idempotent. Control references only.
}

interface PalpateServer {
  # The bootstrap interface (named PalpateServer: a capnp interface called Server
  # would clash with the generated C++ Server class). Each connection gets its own,
  # and the limits per connection (sessions, wrong tokens) count on it.
  version @0 () -> (protocolVersion :UInt32, server :Text);
  # protocolVersion = the constant above as compiled into the server. Answered
  # before authenticate() too, so that a client can tell what it talks to.

  openSession @1 (request :OpenRequest) -> (session :Session, info :SessionInfo, controlToken :Text);
  # Builds the scene's model (off the RPC thread) and starts the session. `session`
  # is the owner's control capability; the session lives while a control reference
  # does (this one, or one attach() gave for the token) and closes when the last
  # goes, read-only views included. controlToken (64 hex digits, 256 bits from the
  # operating system's random source) is returned to the opener only: whoever
  # presents it to attach() controls the session too, so hand it on only to whom
  # you would hand the device. Refused beyond the server's --max-sessions, or the
  # connection's --max-sessions-per-connection (the message names the limit).

  listScenes @2 () -> (names :List(Text));
  # Scene names available under --scene-dir.

  attach @3 (sessionId :UInt32, controlToken :Text) -> (session :Session, info :SessionInfo);
  # Another reference to a live session (e.g. a viewer on its own connection, so
  # that its bytes never share a socket with a haptic client's frames). Without a
  # controlToken (empty) it is a read-only view: subscribe, stats, status and info
  # work, and every command (setForce, setForceVector, setPosition, setCoupling,
  # reset, pause, resume, step, close) is refused; a view does not keep the session
  # alive (when its owner closes it or leaves, the view's subscribers get
  # done("session closed") and its calls fail). With the session's controlToken it
  # is a control reference like the owner's (info.control says which). A wrong
  # token, or an id that names no live session, is refused after a delay, and a
  # connection that has been refused --max-wrong-tokens times is refused every
  # later attach() and authenticate().

  authenticate @4 (accessToken :Text) -> (server :PalpateServer);
  # On a server started with --access-token-file, a connection's bootstrap answers
  # only version() and authenticate() until it presents that token; the capability
  # returned serves everything. A wrong token is refused after a delay (counted like
  # attach()'s). On a server without an access token it returns a capability like
  # the bootstrap, whatever the token.
}