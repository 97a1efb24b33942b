// The viewer's side of the palpate protocol (protocol/palpate.capnp, docs/protocol.md):
// open or attach a session, subscribe to frames, send commands, read statistics. The
// schema's classes come from capnp-es's compiler (build.mjs); frames are copied out of
// the message into plain typed arrays at once, so nothing keeps a message alive.
import { Conn, utils } from "capnp-es";
import { FrameSink, PalpateServer, Session, ToolGuide } from "palpate-schema";
import { WebSocketTransport } from "./transport";

export type Vec3 = [number, number, number];

export interface SessionInfo {
  sessionId: number;
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

export class ViewerSession {
  private subscription: { cancel(): { promise(): Promise<unknown> } } | null = null;
  onFrame: (frame: FrameData) => void = () => {};
  onDone: (reason: string) => void = () => {};

  private constructor(
    readonly transport: WebSocketTransport,
    readonly server: InstanceType<typeof PalpateServer.Client>,
    readonly session: InstanceType<typeof Session.Client>,
    readonly info: SessionInfo,
  ) {}

  // Connects to `url` and opens a session (scene: a name under the server's --scene-dir,
  // or undefined for its default) or, with attachTo, attaches to a live one.
  static async start(
    url: string,
    options: { scene?: string; headless?: boolean; attachTo?: number; overrides?: string[] },
  ): Promise<ViewerSession> {
    const transport = await WebSocketTransport.connect(url);
    const conn = new Conn(transport as never);
    const server = conn.bootstrap(PalpateServer);
    const opened =
      options.attachTo !== undefined
        ? await server.attach((p) => (p.sessionId = options.attachTo!)).promise()
        : await server
            .openSession((p) => {
              const r = p._initRequest();
              if (options.scene) r.scene.name = options.scene;
              else r.scene.serverDefault = true;
              r.headless = !!options.headless;
              const overrides = options.overrides ?? [];
              if (overrides.length > 0) {
                const list = r._initOverrides(overrides.length);
                overrides.forEach((o, i) => list.set(i, o));
              }
            })
            .promise();
    const i = opened.info;
    const info: SessionInfo = {
      sessionId: i.sessionId,
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
    return new ViewerSession(transport, server, opened.session, info);
  }

  get surfaceOnly(): boolean {
    return this.info.surfaceVertices.length > 0;
  }

  // Frames at up to rateHz: the tool and forces always; the body's positions and one
  // display field of its surface vertices (all particles when the body has no surface);
  // the contact set.
  async subscribe(rateHz: number, field: FieldName): Promise<void> {
    await this.unsubscribe();
    const decode = (frame: Parameters<typeof decodeFrame>[0]) => decodeFrame(frame, field, this.transport.lastMessageBytes);
    const sink = new FrameSink.Server({
      frame: async (params) => this.onFrame(decode(params.frame)),
      done: async (params) => this.onDone(params.reason),
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

  async unsubscribe(): Promise<void> {
    // capnp-es never releases capabilities: cancel explicitly.
    if (this.subscription) await this.subscription.cancel().promise();
    this.subscription = null;
  }

  async setForce(newtons: number): Promise<number> {
    const r = await this.session.setForce((p) => (p.newtons = newtons)).promise();
    return Number(r.seq);
  }

  async setPosition(x: Vec3): Promise<number> {
    const r = await this.session
      .setPosition((p) => {
        const v = p._initPosition();
        [v.x, v.y, v.z] = x;
      })
      .promise();
    return Number(r.seq);
  }

  async pause(): Promise<void> {
    await this.session.pause().promise();
  }
  async resume(): Promise<void> {
    await this.session.resume().promise();
  }
  async reset(): Promise<void> {
    await this.session.reset().promise();
  }

  // Headless sessions: n ticks; subscribers get the last frame too.
  async step(n: number): Promise<FrameData> {
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
    await this.unsubscribe();
    await this.session.close().promise();
  }
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
