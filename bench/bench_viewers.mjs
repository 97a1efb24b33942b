// bench/bench_viewers.mjs: what browser viewers cost, in one run (issue #15). Starts
// palpate-server --http and a headless Chromium (tests/browser/cdp.mjs), then, each phase
// on a fresh real-time session pressed with the same force, for --seconds each:
//   none  a page that opens the session and does not subscribe (the loop alone),
//   one   one viewer subscribed (surface positions + the display field at --rate),
//   four  four viewers of the same session (one opens it, three attach: ?session=ID).
// Prints, per phase, each viewer's frames per second and bytes per frame (WebSocket bytes
// received over the window, divided by frames), and the loop's tick lateness and deadline
// misses over the phase (the session's stats). --json FILE writes the same as JSON.
//
//   node bench/bench_viewers.mjs --server build/bin/palpate-server --web-root build/viewer \
//        [--scene scenes/hertz_cube_haptic.json] [--seconds 20] [--rate 30] [--field vonMises]
//        [--force 100] [--json out.json]
import { writeFileSync } from "node:fs";
import { basename, dirname } from "node:path";
import { Browser, sleep, startServer, stopServer } from "../tests/browser/cdp.mjs";

const args = Object.fromEntries(
  process.argv.slice(2).reduce((pairs, a, i, all) => (a.startsWith("--") ? [...pairs, [a.slice(2), all[i + 1]]] : pairs), []),
);
if (!args.server || !args["web-root"]) {
  console.error("usage: node bench_viewers.mjs --server BIN --web-root DIR [--scene FILE] [--seconds S] [--rate HZ] [--field NAME] [--force N] [--json FILE]");
  process.exit(2);
}
const scene = args.scene ?? new URL("../scenes/hertz_cube_haptic.json", import.meta.url).pathname;
const seconds = Number(args.seconds ?? 20);
const rate = Number(args.rate ?? 30);
const field = args.field ?? "displacementMagnitude";
const force = Number(args.force ?? 100);

const server = await startServer(args.server, ["--scene", scene, "--scene-dir", dirname(scene), "--web-root", args["web-root"], "--log-level", "error"]);
const browser = Browser.launch();
const results = { scene: basename(scene), seconds, rateHz: rate, field, forceN: force, phases: [] };

async function phase(name, viewers) {
  const query = `rate=${rate}&field=${field}`;
  const first = await browser.open(`${server.web}?${query}${viewers === 0 ? "&subscribe=0" : ""}`);
  await first.waitFor("window.palpateViewer && palpateViewer.state === 'ready'", `${name}: the session`);
  const id = await first.eval("palpateViewer.session.info.sessionId");
  await first.eval(`palpateViewer.setForce(${force})`);
  const pages = [first];
  for (let k = 1; k < viewers; k++) {
    const p = await browser.open(`${server.web}?${query}&session=${id}`);
    await p.waitFor("window.palpateViewer && palpateViewer.frames > 0", `${name}: viewer ${k + 1}`);
    pages.push(p);
  }
  await sleep(2000); // settle: the press, the pages' first draws
  const read = (p) => p.eval("JSON.stringify({frames: palpateViewer.frames, bytes: palpateViewer.bytesReceived()})").then(JSON.parse);
  const start = await Promise.all(pages.map(read));
  const statsStart = JSON.parse(await first.eval("palpateViewer.stats().then(JSON.stringify)"));
  const t0 = Date.now();
  await sleep(1000 * seconds);
  const end = await Promise.all(pages.map(read));
  const stats = JSON.parse(await first.eval("palpateViewer.stats().then(JSON.stringify)"));
  const window = (Date.now() - t0) / 1000;
  const perViewer = viewers === 0 ? [] : pages.map((_, k) => {
    const frames = end[k].frames - start[k].frames;
    return { framesPerSecond: frames / window, bytesPerFrame: frames > 0 ? (end[k].bytes - start[k].bytes) / frames : 0, bytesPerSecond: (end[k].bytes - start[k].bytes) / window };
  });
  const ticks = stats.ticks - statsStart.ticks;
  const result = {
    phase: name,
    viewers,
    perViewer,
    loop: {
      achievedRateHz: stats.achievedRateHz,
      latenessUsP50: stats.latenessUs.p50,
      latenessUsP99: stats.latenessUs.p99,
      latenessUsMax: stats.latenessUs.max,
      stepUsP50: stats.stepUs.p50,
      stepUsP99: stats.stepUs.p99,
      deadlineMissesInWindow: stats.deadlineMisses - statsStart.deadlineMisses,
      ticksInWindow: ticks,
    },
  };
  for (const p of pages) await p.close();
  return result;
}

let status = 0;
try {
  for (const [name, viewers] of [["none", 0], ["one", 1], ["four", 4]]) results.phases.push(await phase(name, viewers));
} catch (error) {
  console.error(`bench_viewers.mjs: ${error.message}`);
  status = 1;
} finally {
  await browser.close();
  await stopServer(server);
}
const f = (x, d = 1) => (Number.isFinite(x) ? x.toFixed(d) : "–");
console.log(`scene ${results.scene}, ${seconds} s per phase, viewers asking ${rate} frames/s of ${field} on the surface, ${force} N pressed`);
console.log("phase | viewers | frames/s per viewer | bytes/frame | kB/s per viewer | lateness p50 / p99 / max (us) | misses / ticks in the window | step p50 / p99 (us)");
for (const p of results.phases) {
  const fps = p.perViewer.map((v) => f(v.framesPerSecond)).join(", ") || "–";
  const bpf = p.perViewer.map((v) => f(v.bytesPerFrame, 0)).join(", ") || "–";
  const kbs = p.perViewer.map((v) => f(v.bytesPerSecond / 1000)).join(", ") || "–";
  const l = p.loop;
  console.log(`${p.phase} | ${p.viewers} | ${fps} | ${bpf} | ${kbs} | ${f(l.latenessUsP50)} / ${f(l.latenessUsP99)} / ${f(l.latenessUsMax)} | ${l.deadlineMissesInWindow} / ${l.ticksInWindow} | ${f(l.stepUsP50)} / ${f(l.stepUsP99)}`);
}
if (args.json) writeFileSync(args.json, JSON.stringify(results, null, 2) + "\n");
process.exit(status);
