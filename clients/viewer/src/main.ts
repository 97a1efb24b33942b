// The palpate browser viewer (docs/protocol.md, "The browser viewer"). It opens a session
// over WebSocket RPC on the server that served the page, or attaches to a live one, and
// draws what the frames carry.
//
// URL parameters:
//   scene=NAME     a scene of the server's --scene-dir (default: the server's default scene)
//   session=ID     watch a live session instead of opening one (several viewers at once)
//   headless=1     open a headless session: Step buttons advance it
//   field=vonMises the display field (default displacementMagnitude)
//   rate=HZ        frames per second asked of the server (default 30)
//   fmax=N         the force slider's top (default 1.5 x the Hertz force at d = R/5)
//   set=KEY=VALUE  a scene override, repeatable (like --set)
//   subscribe=0    open (or attach) without subscribing to frames (benchmarks: a session
//                  with no viewer)
// window.palpateViewer exposes the state and a few actions for scripts and tests.
import { ForceDepthPlot, hertzForce } from "./plot";
import { COLOUR_BAR_CSS, TissueView } from "./scene3d";
import { type FieldName, type FrameData, type LoopStats, ViewerSession } from "./session";

const params = new URLSearchParams(location.search);
const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const fmt = (x: number, digits = 4) => (Number.isFinite(x) ? x.toPrecision(digits) : "–");

interface ViewerHooks {
  state: "connecting" | "ready" | "error" | "closed";
  error: string;
  frames: number;
  last: FrameData | null;
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
  const status = $("status");
  status.textContent = message;
  status.classList.add("error");
}

async function main(): Promise<void> {
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/rpc`;
  const attachTo = params.has("session") ? Number(params.get("session")) : undefined;
  const field = (params.get("field") ?? "displacementMagnitude") as FieldName;
  const rateHz = Number(params.get("rate") ?? 30);
  const viewer = await ViewerSession.start(url, {
    scene: params.get("scene") ?? undefined,
    headless: params.get("headless") === "1",
    attachTo,
    overrides: params.getAll("set"),
  });
  const info = viewer.info;
  hooks.session = viewer;
  viewer.transport.onClose = (reason) => {
    hooks.state = "closed";
    fail(`disconnected: ${reason}`);
  };

  $("scene").textContent =
    `${info.sceneName}: ${info.particleCount} particles, ${info.headless ? "headless" : `${info.rateHz} Hz`}, ` +
    `tool radius ${fmt(1000 * info.radius, 3)} mm, E = ${fmt(info.youngModulus, 3)} Pa`;
  $("share").innerHTML = `Session ${info.sessionId}. Others can watch it at <a href="?session=${info.sessionId}">?session=${info.sessionId}</a>.`;
  for (const b of document.querySelectorAll<HTMLButtonElement>(".headless")) b.disabled = !info.headless;
  $<HTMLButtonElement>("pause").disabled = info.headless;
  $("drag-hint").style.display = info.freeGuide ? "" : "none";
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
  slider.addEventListener("input", () => {
    showForce();
    const sent = performance.now();
    viewer.setForce(Number(slider.value) * fmax).then((seq) => track(seq, sent), (e) => fail(String(e)));
  });
  showForce();
  hooks.setForce = async (newtons: number) => {
    slider.value = String(newtons / fmax);
    showForce();
    const sent = performance.now();
    const seq = await viewer.setForce(newtons);
    track(seq, sent);
    return seq;
  };

  let paused = false;
  $("pause").addEventListener("click", async () => {
    paused = !paused;
    await (paused ? viewer.pause() : viewer.resume());
    $("pause").textContent = paused ? "Resume" : "Pause";
  });
  $("reset").addEventListener("click", async () => {
    await viewer.reset();
    plot.clear();
  });
  hooks.step = (n: number) => viewer.step(n);
  $("step1").addEventListener("click", () => viewer.step(1).catch((e) => fail(String(e))));
  $("step100").addEventListener("click", () => viewer.step(100).catch((e) => fail(String(e))));
  $("field").addEventListener("change", () => {
    const next = new URLSearchParams(location.search);
    next.set("field", $<HTMLSelectElement>("field").value);
    if (!next.has("session")) next.set("session", String(info.sessionId));
    location.search = next.toString();  // a new subscription with the other field
  });

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
    viewer.setPosition(target).then((seq) => track(seq, sent), (e) => fail(String(e)));
  };
  canvas.addEventListener("pointerdown", (event) => {
    if (!info.freeGuide || !event.shiftKey) return;
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
  viewer.onDone = (reason) => fail(`the server ended the stream: ${reason}`);
  hooks.bytesReceived = () => viewer.transport.bytesReceived;
  if (params.get("subscribe") !== "0") await viewer.subscribe(rateHz, field);
  else hooks.state = "ready";

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

  const fieldUnit = field === "vonMises" ? { name: "von Mises stress (Pa)", scale: 1 } : { name: "displacement |u| (mm)", scale: 1000 };
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
      $("status").textContent = frame.recoveries > 0 ? `${frame.recoveries} blow-up(s) recovered` : "live";
      if (hooks.state === "connecting") hooks.state = "ready";
    }
    view.render();
    requestAnimationFrame(animate);
  };
  requestAnimationFrame(animate);
  $("status").textContent = "waiting for frames…";
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
      fail(String(e));
      return;
    }
    setTimeout(poll, 1000);
  };
  setTimeout(poll, 1000);
}

main().catch((e) => fail(`cannot start: ${e instanceof Error ? e.message : String(e)}`));
