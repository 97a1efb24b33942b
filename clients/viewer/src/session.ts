// The viewer's side of the palpate protocol (protocol/palpate.capnp, docs/protocol.md):
// open or attach a session, subscribe to frames, send commands, read statistics. The
// schema's classes come from capnp-es's compiler (build.mjs); frames are copied out of
// the message into plain typed arrays at once, so nothing keeps a message alive.
//
// A session belongs to its opener (docs/protocol.md, "Security model"): openSession gives
// the control capability and a control token; attach() without the token gives a
// read-only view (subscribe, stats, status, info), with it a control reference. The
// session lives only while a control reference does.
import { Conn, utils } from "capnp-es";
import { FrameSink, PalpateServer, Session, ToolGuide } from "palpate-schema";
import { WebSocketTransport } from "./transport";

export type Vec3 = [number, number, number];

export interface SessionInfo {
  sessionId: number;
  control: boolean; // this page may command the session; false: a read-only view
  sceneName: string;
  particleCount: number;
  dt: number; // s
  rateHz: number; // 0 for headless
  headless: boolean;
  forceLimit: number; // N
  restPositions: Float32Array; // 3 n, m
  surfaceTriangles: Uint32Array; // particle indices, 3 per triangle
  surfaceVertices: Uint32Array; // ascending particle indices: the order of surface-only frames
  touchHeight: number; // m
  radius: number; // m
  youngModulus: number; // Pa
  poissonRatio: number;
  workspaceMin: Vec3; // m
  workspaceMax: Vec3;
  freeGuide: boolean;
  // The server's stored finite-block reference of this scene (empty when it has none).
  reference: { forces: Float64Array; indentation: Float64Array; uncertainty: Float64Array };
}

export type FieldName = "displacementMagnitude" | "vonMises" | "none";

export interface FrameData {
  tick: number;
  simTime: number; // s
  indenterPosition: Vec3; // m
  indentation: number; // m
  toolContactForce: Vec3; // N, on the tool
  forceCommand: number; // N, pressing
  commandSeq: number;
  recoveries: number;
  positionMode: boolean;
  target: Vec3;
  positions: Float32Array | null; // 3 per particle (or per surface vertex when surfaceOnly)
  field: Float32Array | null; // the subscribed display field, same order
  contactNodes: Uint32Array;
  contactForces: Float32Array;
  bytes: number; // size of the WebSocket message that carried it
}

export interface LoopStats {
  ticks: number;
  elapsedSeconds: number;
  targetRateHz: number;
  achievedRateHz: number;
  stepUs: { p50: number; p99: number; max: number };
  latenessUs: { p50: number; p99: number; max: number };
  deadlineMisses: number;
  blowUps: number;
}

const vec3 = (v: { x: number; y: number; z: number }): Vec3 => [v.x, v.y, v.z];

// What a view is refused (the server refuses it too; refusing here says why without a
// round trip, and reaches the page's scripts as a rejection).
export class ReadOnlyError extends Error {
  constructor(method: string, sessionId: number) {
    super(`${method}: read-only: this page watches session ${sessionId} without control (open the session's control link to command it)`);
    this.name = "ReadOnlyError";
  }
}

// A call that failed because the session is gone (its owner closed it or left), as the
// server words it for a view ("has ended") and for a control reference ("is closed").
export const sessionEnded = (error: unknown): boolean =>
  /has ended|session is closed/.test(error instanceof Error ? error.message : String(error));

// A list's elements as a typed array: a copy of the bytes in place when they are aligned
// for the element type (the normal case), else element by element.
function copyList<T extends Float32Array | Uint32Array>(
  list: { length: number; get(i: number): number },
  Make: { new (n: number): T; new (b: ArrayBuffer, o: number, n: number): T; BYTES_PER_ELEMENT: number },
): T {
  const n = list.length;
  const out = new Make(n);
  if (n === 0) return out;
  try {
    const content = utils.getContent(list as never) as unknown as { segment: { buffer: ArrayBuffer }; byteOffset: number };
    if (content.byteOffset % Make.BYTES_PER_ELEMENT === 0) {
      out.set(new Make(content.segment.buffer, content.byteOffset, n));
      if (out[0] === list.get(0) && out[n - 1] === list.get(n - 1)) return out;
    }
  } catch {
    // fall through to the element-wise copy
  }
  for (let i = 0; i < n; i++) out[i] = list.get(i);
  return out;
}

type ServerClient = InstanceType<typeof PalpateServer.Client>;
type SessionClient = InstanceType<typeof Session.Client>;
type WireInfo = Awaited<ReturnType<ReturnType<ServerClient["attach"]>["promise"]>>["info"];
type Opened = { session: SessionClient; info: WireInfo; controlToken: string };

export interface StartOptions {
  scene?: string; // a name under the server's --scene-dir (default: its default scene)
  headless?: boolean;
  attachTo?: number; // a live session's id: attach instead of opening one
  controlToken?: string; // with attachTo: the session's control token (without: a read-only view)
  accessToken?: string; // the server's access token (--access-token-file): authenticate first
  overrides?: string[];
}

export class ViewerSession {
  private subscription: { cancel(): { promise(): Promise<unknown> } } | null = null;
  // Bumped by every (un)subscribe: frames and done() of an earlier subscription, still on
  // their way when it was cancelled, are dropped (a field change must not end the page).
  private generation = 0;
  // (Re)subscriptions one after the other, so that a quick second change cannot leave a
  // subscription nobody cancels (capnp-es never releases it).
  private subscribing: Promise<unknown> = Promise.resolve();
  onFrame: (frame: FrameData) => void = () => {};
  onDone: (reason: string) => void = () => {};

  private constructor(
    readonly transport: WebSocketTransport,
    readonly server: ServerClient,
    readonly session: SessionClient,
    readonly info: SessionInfo,
    // The token that controls this session ("" on a view): openSession's for the opener,
    // the one attach() accepted for a controller. Whoever has it commands the tool.
    readonly controlToken: string,
  ) {}

  // Connects to `url` and opens a session or, with attachTo, attaches to a live one:
  // read-only without controlToken, in control with it.
  static async start(url: string, options: StartOptions): Promise<ViewerSession> {
    const transport = await WebSocketTransport.connect(url);
    const conn = new Conn(transport as never);
    let server = conn.bootstrap(PalpateServer);
    if (options.accessToken) {
      const token = options.accessToken;
      server = (await server.authenticate((p) => (p.accessToken = token)).promise()).server;
    }
    const opened =
      options.attachTo !== undefined ? await attach(server, options.attachTo, options.controlToken ?? "") : await open(server, options);
    return new ViewerSession(transport, server, opened.session, decodeInfo(opened.info), opened.controlToken);
  }

  get surfaceOnly(): boolean {
    return this.info.surfaceVertices.length > 0;
  }

  // Frames at up to rateHz: the tool and forces always; the body's positions and one
  // display field of its surface vertices (all particles when the body has no surface);
  // the contact set. Replaces the current subscription, if any (cancelled first).
  subscribe(rateHz: number, field: FieldName): Promise<void> {
    const next = this.subscribing.then(() => this.resubscribe(rateHz, field));
    this.subscribing = next.catch(() => {});
    return next;
  }

  private async resubscribe(rateHz: number, field: FieldName): Promise<void> {
    await this.cancelSubscription();
    const mine = ++this.generation;
    const current = () => mine === this.generation;
    const decode = (frame: Parameters<typeof decodeFrame>[0]) => decodeFrame(frame, field, this.transport.lastMessageBytes);
    const sink = new FrameSink.Server({
      frame: async (params) => {
        if (current()) this.onFrame(decode(params.frame));
      },
      done: async (params) => {
        if (current()) this.onDone(params.reason);
      },
    });
    const result = await this.session
      .subscribe((p) => {
        p.sink = sink.client();
        const o = p._initOptions();
        o.rateHz = rateHz;
        const f = o._initFields();
        f.positions = true;
        f.contacts = true;
        f.displacementMagnitude = field === "displacementMagnitude";
        f.vonMises = field === "vonMises";
        f.surfaceOnly = this.surfaceOnly;
      })
      .promise();
    this.subscription = result.subscription;
  }

  unsubscribe(): Promise<void> {
    const next = this.subscribing.then(() => this.cancelSubscription());
    this.subscribing = next.catch(() => {});
    return next;
  }

  private async cancelSubscription(): Promise<void> {
    this.generation++; // its done("subscription cancelled") is ours, not the session's end
    // capnp-es never releases capabilities: cancel explicitly.
    const subscription = this.subscription;
    this.subscription = null;
    if (subscription) await subscription.cancel().promise();
  }

  // Commands: refused on a read-only view without sending anything.
  private requireControl(method: string): void {
    if (!this.info.control) throw new ReadOnlyError(method, this.info.sessionId);
  }

  async setForce(newtons: number): Promise<number> {
    this.requireControl("setForce");
    const r = await this.session.setForce((p) => (p.newtons = newtons)).promise();
    return Number(r.seq);
  }

  async setPosition(x: Vec3): Promise<number> {
    this.requireControl("setPosition");
    const r = await this.session
      .setPosition((p) => {
        const v = p._initPosition();
        [v.x, v.y, v.z] = x;
      })
      .promise();
    return Number(r.seq);
  }

  async pause(): Promise<void> {
    this.requireControl("pause");
    await this.session.pause().promise();
  }
  async resume(): Promise<void> {
    this.requireControl("resume");
    await this.session.resume().promise();
  }
  async reset(): Promise<void> {
    this.requireControl("reset");
    await this.session.reset().promise();
  }

  // Headless sessions: n ticks; subscribers get the last frame too.
  async step(n: number): Promise<FrameData> {
    this.requireControl("step");
    const r = await this.session
      .step((p) => {
        p.n = n;
        const f = p._initFields();
        f.positions = true;
        f.surfaceOnly = this.surfaceOnly;
      })
      .promise();
    return decodeFrame(r.frame, "none", this.transport.lastMessageBytes);
  }

  async stats(): Promise<LoopStats> {
    const s = (await this.session.stats().promise()).stats;
    const pct = (p: { p50: number; p99: number; max: number }) => ({ p50: p.p50, p99: p.p99, max: p.max });
    return {
      ticks: Number(s.ticks),
      elapsedSeconds: s.elapsedSeconds,
      targetRateHz: s.targetRateHz,
      achievedRateHz: s.achievedRateHz,
      stepUs: pct(s.stepUs),
      latenessUs: pct(s.latenessUs),
      deadlineMisses: Number(s.deadlineMisses),
      blowUps: s.blowUps,
    };
  }

  async close(): Promise<void> {
    this.requireControl("close");
    await this.unsubscribe();
    await this.session.close().promise();
  }
}

// openSession: the scene by name (or the server's default), the owner's capability and token.
async function open(server: ServerClient, options: StartOptions): Promise<Opened> {
  const r = await server
    .openSession((p) => {
      const request = p._initRequest();
      if (options.scene) request.scene.name = options.scene;
      else request.scene.serverDefault = true;
      request.headless = !!options.headless;
      const overrides = options.overrides ?? [];
      if (overrides.length > 0) {
        const list = request._initOverrides(overrides.length);
        overrides.forEach((o, i) => list.set(i, o));
      }
    })
    .promise();
  return { session: r.session, info: r.info, controlToken: r.controlToken };
}

// attach: a read-only view with an empty token, a control reference with the session's.
async function attach(server: ServerClient, sessionId: number, controlToken: string): Promise<Opened> {
  const r = await server
    .attach((p) => {
      p.sessionId = sessionId;
      p.controlToken = controlToken;
    })
    .promise();
  return { session: r.session, info: r.info, controlToken: r.info.control ? controlToken : "" };
}

function decodeInfo(i: WireInfo): SessionInfo {
  return {
    sessionId: i.sessionId,
    control: i.control,
    sceneName: i.sceneName,
    particleCount: i.particleCount,
    dt: i.dt,
    rateHz: i.rateHz,
    headless: i.headless,
    forceLimit: i.forceLimit,
    restPositions: copyList(i.restPositions, Float32Array),
    surfaceTriangles: copyList(i.surfaceTriangles, Uint32Array),
    surfaceVertices: copyList(i.surfaceVertices, Uint32Array),
    touchHeight: i.touchHeight,
    radius: i.radius,
    youngModulus: i.youngModulus,
    poissonRatio: i.poissonRatio,
    workspaceMin: vec3(i.workspaceMin),
    workspaceMax: vec3(i.workspaceMax),
    freeGuide: i.guide === ToolGuide.FREE,
    reference: {
      forces: Float64Array.from(i.referenceForces.toArray()),
      indentation: Float64Array.from(i.referenceIndentation.toArray()),
      uncertainty: Float64Array.from(i.referenceUncertainty.toArray()),
    },
  };
}

type WireFrame = Parameters<NonNullable<ConstructorParameters<typeof FrameSink.Server>[0]["frame"]>>[0]["frame"];

export function decodeFrame(f: WireFrame, field: FieldName, bytes: number): FrameData {
  const list =
    field === "displacementMagnitude" && f._hasDisplacementMagnitude()
      ? f.displacementMagnitude
      : field === "vonMises" && f._hasVonMises()
        ? f.vonMises
        : null;
  return {
    tick: Number(f.tick),
    simTime: f.simTime,
    indenterPosition: vec3(f.indenterPosition),
    indentation: f.indentation,
    toolContactForce: vec3(f.toolContactForce),
    forceCommand: f.forceCommand,
    commandSeq: Number(f.commandSeq),
    recoveries: f.recoveries,
    positionMode: f.mode === 1,
    target: vec3(f.target),
    positions: f._hasPositions() ? copyList(f.positions, Float32Array) : null,
    field: list ? copyList(list, Float32Array) : null,
    contactNodes: f._hasContactNodes() ? copyList(f.contactNodes, Uint32Array) : new Uint32Array(0),
    contactForces: f._hasContactForces() ? copyList(f.contactForces, Float32Array) : new Float32Array(0),
    bytes,
  };
}
