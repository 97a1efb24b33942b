// The palpate browser viewer (docs/protocol.md, "The browser viewer"). It opens a session
// over WebSocket RPC on the server that served the page, or attaches to a live one, and
// draws what the frames carry.
//
// A session lives while a page (or client) in control of it stays connected: closing or
// reloading the page that opened it ends it for everyone watching, unless a page opened
// with its control link still holds it. So the page never reloads itself.
//
// URL parameters:
//   scene=NAME     a scene of the server's --scene-dir (default: the server's default scene)
//   session=ID     watch a live session read-only instead of opening one (several viewers
//                  at once): frames and statistics, every command disabled. The watch link
//                  a page shows.
//   token=HEX      with session=ID: the session's control token, to command it as its
//                  opener does (the control link the opener's page shows: whoever has it
//                  controls the tool)
//   headless=1     open a headless session: Step buttons advance it
//   field=vonMises the display field (default displacementMagnitude); changing it on the
//                  page subscribes again in place
//   rate=HZ        frames per second asked of the server (default 30)
//   fmax=N         the force slider's top (default 1.5 x the Hertz force at d = R/5)
//   set=KEY=VALUE  a scene override, repeatable (like --set)
//   subscribe=0    open (or attach) without subscribing to frames (benchmarks: a session
//                  with no viewer)
// and in the fragment (never sent to any server, and removed from the address bar at once):
//   #access=TOKEN  the server's access token (palpate-server --access-token-file), presented
//                  with PalpateServer.authenticate before anything else. The links the page
//                  shows do not carry it: whoever follows them needs it too.
// window.palpateViewer exposes the state and a few actions for scripts and tests.
import { ForceDepthPlot, hertzForce } from "./plot";
import { COLOUR_BAR_CSS, TissueView } from "./scene3d";
import { type FieldName, type FrameData, type LoopStats, type SessionInfo, ViewerSession, sessionEnded } from "./session";

const params = new URLSearchParams(location.search);
// The access token, read once from the fragment and then dropped from the address bar (and
// the history entry), so that a shared screen or a copied address does not carry it.
const accessToken = new URLSearchParams(location.hash.slice(1)).get("access") ?? undefined;
if (accessToken !== undefined) history.replaceState(null, "", `${location.pathname}${location.search}`);
const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const fmt = (x: number, digits = 4) => (Number.isFinite(x) ? x.toPrecision(digits) : "–");

interface ViewerHooks {
  state: "connecting" | "ready" | "error" | "closed" | "ended"; // ended: the session is gone
  error: string;
  frames: number;
  last: FrameData | null;
  field: FieldName; // the display field subscribed
  fieldMax: number;
  session?: ViewerSession;
  setForce(newtons: number): Promise<number>;
  step(n: number): Promise<FrameData>;
  stats(): Promise<LoopStats>;
  maxDisplacement(): number;
  canvasStats(): { drawn: number; colours: number };
  bytesReceived(): number; // WebSocket bytes received so far (frames and replies)
}
const hooks: ViewerHooks = {
  state: "connecting",
  error: "",
  frames: 0,
  last: null,
  field: "displacementMagnitude",
  fieldMax: 0,
  setForce: () => Promise.reject(new Error("not connected")),
  step: () => Promise.reject(new Error("not connected")),
  stats: () => Promise.reject(new Error("not connected")),
  maxDisplacement: () => 0,
  canvasStats: () => ({ drawn: 0, colours: 0 }),
  bytesReceived: () => 0,
};
(window as unknown as { palpateViewer: ViewerHooks }).palpateViewer = hooks;

function fail(message: string): void {
  hooks.state = "error";
  hooks.error = message;
  $("status-text").textContent = message;
  $("status").classList.add("error");
}

// The session is gone (its owner closed it or left, or the server stops): said in the
// status area, and nothing is commanded any more.
function ended(info: SessionInfo, why: string): void {
  if (hooks.state === "ended") return;
  hooks.state = "ended";
  hooks.error = `Session ${info.sessionId} has ended: ${why}`;
  $("status-text").textContent = hooks.error;
  $("status").classList.add("ended");
  enableCommands(info, false);
}

const message = (e: unknown) => (e instanceof Error ? e.message : String(e));

// Every command control of the page: a read-only view, or an ended session, has none.
function enableCommands(info: SessionInfo, control: boolean): void {
  $<HTMLInputElement>("force").disabled = !control;
  $<HTMLButtonElement>("pause").disabled = !control || info.headless;
  $<HTMLButtonElement>("reset").disabled = !control;
  for (const b of document.querySelectorAll<HTMLButtonElement>(".headless")) b.disabled = !control || !info.headless;
  $<HTMLInputElement>("press-depth").disabled = !control;
  $("drag-hint").style.display = control && info.freeGuide ? "" : "none";
  $("read-only").hidden = control || hooks.state === "ended";
}

// Who this page is to the session, first in the status area: a view says so at all times.
function showRole(info: SessionInfo, opened: boolean): void {
  const role = $("role");
  role.hidden = opened;
  role.textContent = info.control ? `Controlling session ${info.sessionId}` : `Watching session ${info.sessionId} read-only`;
  role.classList.toggle("read-only", !info.control);
}

// The links to this session. The watch link (?session=ID) gives a read-only view; the
// control link (?session=ID&token=…) gives what the opener has, so only a page in control
// shows it, apart and with a warning, and only the token's first digits are on screen (a
// shared screen shows the page). Both open a new tab: leaving the opener's page would end
// the session.
function showShare(info: SessionInfo, controlToken: string, opened: boolean): void {
  const base = `${location.origin}${location.pathname}`;
  const link = (query: string, text: string) => {
    const a = document.createElement("a");
    a.href = `${base}${query}`;
    a.target = "_blank";
    a.rel = "noopener";
    a.textContent = text;
    return a;
  };
  const watch = `?session=${info.sessionId}`;
  const share = $("share");
  share.replaceChildren(
    info.control ? `Session ${info.sessionId}. Watch link (read-only): ` : `Watching session ${info.sessionId} read-only. Watch link: `,
    link(watch, watch),
    opened ? ". The session ends when this page closes or reloads." : ".",
    accessToken !== undefined ? " This server asks for its access token: add #access=… to a link you share." : "",
  );
  const control = $("control-link");
  control.hidden = !controlToken;
  if (!controlToken) return;
  const query = `${watch}&token=${controlToken}`;
  control.replaceChildren(
    "Control link: ",
    link(query, `${watch}&token=${controlToken.slice(0, 8)}…`),
    " gives control of the tool: share only with whom you would hand the device.",
  );
}

async function main(): Promise<void> {
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/rpc`;
  const attachTo = params.has("session") ? Number(params.get("session")) : undefined;
  let field = (params.get("field") ?? "displacementMagnitude") as FieldName;
  const rateHz = Number(params.get("rate") ?? 30);
  const viewer = await ViewerSession.start(url, {
    scene: params.get("scene") ?? undefined,
    headless: params.get("headless") === "1",
    attachTo,
    controlToken: params.get("token") ?? undefined,
    accessToken,
    overrides: params.getAll("set"),
  });
  const info = viewer.info;
  const opened = attachTo === undefined;
  hooks.session = viewer;
  hooks.field = field;
  viewer.transport.onClose = (reason) => {
    if (hooks.state === "ended") return; // the server said why already
    hooks.state = "closed";
    fail(`disconnected: ${reason}`);
  };
  // A command or a read that failed: the session's end, said as such, or an error. The
  // server says why a view's session ended in brackets ("… has ended (its owner closed it
  // or left)"); a control reference's call after Session.close finds it "closed".
  const failed = (e: unknown) =>
    sessionEnded(e) ? ended(info, /has ended \(([^)]*)\)/.exec(message(e))?.[1] ?? "session closed") : fail(message(e));

  $("scene").textContent =
    `${info.sceneName}: ${info.particleCount} particles, ${info.headless ? "headless" : `${info.rateHz} Hz`}, ` +
    `tool radius ${fmt(1000 * info.radius, 3)} mm, E = ${fmt(info.youngModulus, 3)} Pa`;
  showRole(info, opened);
  showShare(info, viewer.controlToken, opened);
  enableCommands(info, info.control);
  $<HTMLInputElement>("press-depth").value = fmt(1000 * 0.1 * info.radius, 2);
  $("bar").style.background = COLOUR_BAR_CSS;
  $<HTMLSelectElement>("field").value = field;

  const view = new TissueView($<HTMLCanvasElement>("view"), info);
  const plot = new ForceDepthPlot($<HTMLCanvasElement>("plot"), info.radius, info.youngModulus, info.poissonRatio, info.reference);

  // The force slider: 0 ... fmax N, pressing down.
  const fmax = Number(params.get("fmax") ?? 0) || Math.min(info.forceLimit, 1.5 * hertzForce(info.radius / 5, info.radius, info.youngModulus, info.poissonRatio));
  const slider = $<HTMLInputElement>("force");
  const pending: { seq: number; sent: number }[] = [];
  const latencies: number[] = [];
  const track = (seq: number, sent: number) => {
    if (seq > 0) pending.push({ seq, sent });
  };
  const showForce = () => ($("force-value").textContent = `${fmt(Number(slider.value) * fmax, 3)} N`);
  // A view's slider shows the force in effect, which others command.
  const showCommanded = (newtons: number) => {
    slider.value = String(Math.min(Math.max(newtons / fmax, 0), 1));
    $("force-value").textContent = `${fmt(newtons, 3)} N`;
  };
  slider.addEventListener("input", () => {
    showForce();
    const sent = performance.now();
    viewer.setForce(Number(slider.value) * fmax).then((seq) => track(seq, sent), failed);
  });
  showForce();
  // On a view, rejects (read-only) without sending and leaves the slider as it is.
  hooks.setForce = async (newtons: number) => {
    const sent = performance.now();
    const seq = await viewer.setForce(newtons);
    slider.value = String(newtons / fmax);
    showForce();
    track(seq, sent);
    return seq;
  };

  let paused = false;
  $("pause").addEventListener("click", () => {
    const pausing = !paused;
    (pausing ? viewer.pause() : viewer.resume()).then(() => {
      paused = pausing;
      $("pause").textContent = paused ? "Resume" : "Pause";
    }, failed);
  });
  $("reset").addEventListener("click", () => viewer.reset().then(() => plot.clear(), failed));
  hooks.step = (n: number) => viewer.step(n);
  $("step1").addEventListener("click", () => viewer.step(1).catch(failed));
  $("step100").addEventListener("click", () => viewer.step(100).catch(failed));

  // Shift-drag on a free tool: position commands at the picked surface point, pressing
  // the chosen depth below it (the tool's centre R - depth above the point).
  const canvas = $<HTMLCanvasElement>("view");
  let dragging = false;
  const moveTool = (event: PointerEvent) => {
    const rect = canvas.getBoundingClientRect();
    const hit = view.pick(((event.clientX - rect.left) / rect.width) * 2 - 1, -((event.clientY - rect.top) / rect.height) * 2 + 1);
    if (!hit) return;
    const depth = Number($<HTMLInputElement>("press-depth").value) / 1000;
    const target: [number, number, number] = [hit.x, hit.y, hit.z + info.radius - depth];
    for (let c = 0; c < 3; c++) target[c] = Math.min(Math.max(target[c], info.workspaceMin[c]), info.workspaceMax[c]);
    const sent = performance.now();
    viewer.setPosition(target).then((seq) => track(seq, sent), failed);
  };
  canvas.addEventListener("pointerdown", (event) => {
    if (!info.control || hooks.state === "ended" || !info.freeGuide || !event.shiftKey) return;
    dragging = true;
    view.controls.enabled = false;
    canvas.setPointerCapture(event.pointerId);
    moveTool(event);
  });
  canvas.addEventListener("pointermove", (event) => dragging && moveTool(event));
  canvas.addEventListener("pointerup", () => {
    dragging = false;
    view.controls.enabled = true;
  });

  // Frames.
  let bytes = 0;
  let frameCount = 0;
  let windowStart = performance.now();
  let newest: FrameData | null = null;
  viewer.onFrame = (frame) => {
    hooks.frames++;
    hooks.last = frame;
    newest = frame;
    frameCount++;
    bytes += frame.bytes;
    while (pending.length > 0 && frame.commandSeq >= pending[0].seq) {
      latencies.push(performance.now() - pending.shift()!.sent);
      if (latencies.length > 50) latencies.shift();
    }
  };
  viewer.onDone = (reason) => ended(info, reason);
  hooks.bytesReceived = () => viewer.transport.bytesReceived;
  const subscribed = params.get("subscribe") !== "0";
  if (subscribed) await viewer.subscribe(rateHz, field);
  else hooks.state = "ready";

  // Another field: the same session, subscribed again in place. Reloading the page would
  // end the session (the opener's connection holds it) and a view's too.
  const fieldUnits = () => (field === "vonMises" ? { name: "von Mises stress (Pa)", scale: 1 } : { name: "displacement |u| (mm)", scale: 1000 });
  let fieldUnit = fieldUnits();
  $("field").addEventListener("change", () => {
    field = $<HTMLSelectElement>("field").value as FieldName;
    hooks.field = field;
    fieldUnit = fieldUnits();
    $("field-name").textContent = fieldUnit.name;
    view.fieldRange = 0; // the colour bar starts over in the new field's units
    newest = null;
    const next = new URLSearchParams(location.search);
    next.set("field", field);
    history.replaceState(null, "", `?${next}`);
    if (subscribed && hooks.state !== "ended") viewer.subscribe(rateHz, field).catch(failed);
  });

  hooks.maxDisplacement = () => view.maxDisplacement();
  hooks.stats = () => viewer.stats();
  hooks.canvasStats = () => {
    const small = document.createElement("canvas");
    small.width = 96;
    small.height = 72;
    const g = small.getContext("2d")!;
    g.drawImage(canvas, 0, 0, small.width, small.height);
    const pixels = g.getImageData(0, 0, small.width, small.height).data;
    const background = [0x1b, 0x1e, 0x24];
    let drawn = 0;
    const colours = new Set<number>();
    for (let i = 0; i < pixels.length; i += 4) {
      const d = Math.abs(pixels[i] - background[0]) + Math.abs(pixels[i + 1] - background[1]) + Math.abs(pixels[i + 2] - background[2]);
      if (d > 12) drawn++;
      colours.add(((pixels[i] >> 4) << 8) | ((pixels[i + 1] >> 4) << 4) | (pixels[i + 2] >> 4));
    }
    return { drawn: drawn / (pixels.length / 4), colours: colours.size };
  };

  $("field-name").textContent = fieldUnit.name;
  const animate = () => {
    if (newest) {
      const frame = newest;
      newest = null;
      hooks.fieldMax = view.update(frame);
      $("bar-max").textContent = fmt(view.fieldRange * fieldUnit.scale, 3);
      const fz = frame.toolContactForce[2];
      plot.add(frame.indentation, fz);
      plot.draw();
      $("tick").textContent = `${frame.tick} (${fmt(frame.simTime, 4)} s)`;
      $("depth").textContent = `${fmt(1000 * frame.indentation)} mm`;
      $("contact").textContent = `${fmt(fz)} N (command ${fmt(frame.forceCommand)} N)`;
      $("hertz").textContent = `${fmt(hertzForce(frame.indentation, info.radius, info.youngModulus, info.poissonRatio))} N`;
      $("patch").textContent = String(frame.contactNodes.length);
      if (hooks.state !== "ended") $("status-text").textContent = frame.recoveries > 0 ? `${frame.recoveries} blow-up(s) recovered` : "live";
      if (!info.control) showCommanded(frame.forceCommand);
      if (hooks.state === "connecting") hooks.state = "ready";
    }
    view.render();
    requestAnimationFrame(animate);
  };
  requestAnimationFrame(animate);
  $("status-text").textContent = "waiting for frames…";
  if (info.headless) hooks.state = "ready";

  // The loop's health once a second, and this view's bandwidth.
  const poll = async () => {
    try {
      const s = await viewer.stats();
      const seconds = (performance.now() - windowStart) / 1000;
      $("rate").textContent = info.headless ? "headless" : `${fmt(s.achievedRateHz, 5)} of ${s.targetRateHz} Hz`;
      $("lateness").textContent = `${fmt(s.latenessUs.p50, 3)} / ${fmt(s.latenessUs.p99, 3)} µs`;
      $("misses").textContent = `${s.deadlineMisses} of ${s.ticks}`;
      $("step-time").textContent = `${fmt(s.stepUs.p50, 3)} / ${fmt(s.stepUs.p99, 3)} µs`;
      const sorted = [...latencies].sort((a, b) => a - b);
      $("latency").textContent = sorted.length ? `${fmt(sorted[sorted.length >> 1], 3)} ms median` : "–";
      $("bandwidth").textContent = `${fmt(frameCount / seconds, 3)}, ${frameCount ? Math.round(bytes / frameCount) : 0} B`;
      frameCount = 0;
      bytes = 0;
      windowStart = performance.now();
    } catch (e) {
      failed(e);
      return;
    }
    setTimeout(poll, 1000);
  };
  setTimeout(poll, 1000);
}

main().catch((e) => fail(`cannot start: ${message(e)}`));
