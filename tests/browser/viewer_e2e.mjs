// The browser viewer end to end, in a real headless Chromium (ctest viewer_browser_e2e):
//   1. palpate-server --http serves the page; a tab opens a real-time session of the
//      accurate haptic scene and must receive frames and draw (the canvas is not blank);
//   2. the force slider's hook presses the tool: the tissue surface the page draws moves
//      (its largest displacement grows past a tenth of the Hertz depth at that force), the
//      page decodes a positive indentation, and a screenshot is written;
//   3. other tabs on the same session: the watch link (?session=ID) gives a read-only view
//      (frames, info.control false, every command control disabled, "Watching session ID
//      read-only" in the status area, setForce rejected, no control link shown, a
//      screenshot); the control link (?session=ID&token=TOKEN, the opener's token) gives
//      control, and its force reaches the opener's frames; changing the display field in
//      the opener's tab subscribes again in place (no reload, same session, frames of the
//      new field); the controller leaving keeps the session, the opener leaving ends it
//      and the watcher says so;
//   4. a headless session stepped by the page to a tick gives the indentation that
//      palpate-client (C++, TCP) decodes for the same scene, force and tick, to the bit;
//   5. on a server with --access-token-file, a page without the token is refused and one
//      with #access=TOKEN opens a session (the token leaves the address bar).
//
//   node viewer_e2e.mjs --server BIN --client BIN --scenes DIR --web-root DIR --out DIR
// Exit status 0 when every check passed; the last line says "N passed, M failed".
import { execFileSync } from "node:child_process";
import { mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { join } from "node:path";
import { Browser, sleep, startServer, stopServer } from "./cdp.mjs";

const args = Object.fromEntries(
  process.argv.slice(2).reduce((pairs, a, i, all) => (a.startsWith("--") ? [...pairs, [a.slice(2), all[i + 1]]] : pairs), []),
);
for (const key of ["server", "client", "scenes", "web-root", "out"]) {
  if (!args[key]) {
    console.error(`viewer_e2e.mjs: --${key} is required`);
    process.exit(2);
  }
}
mkdirSync(args.out, { recursive: true });

let passed = 0;
let failed = 0;
function check(ok, what, detail = "") {
  if (ok) passed++;
  else failed++;
  console.log(`${ok ? "ok  " : "FAIL"} ${what}${detail ? ` (${detail})` : ""}`);
}

const scene = "hertz_cube_haptic";
const server = await startServer(args.server, [
  "--scene-dir", args.scenes,
  "--scene", join(args.scenes, `${scene}.json`),
  "--web-root", args["web-root"],
  "--log-level", "error",
]);
console.log(`server: rpc ${server.rpc}, web ${server.web}`);
const browser = Browser.launch();
try {
  // 1. A real-time session: frames arrive and the canvas shows something.
  const page = await browser.open(server.web);
  await page.waitFor("window.palpateViewer && palpateViewer.state === 'ready' && palpateViewer.frames >= 5", "the first frames");
  const before = JSON.parse(await page.eval("JSON.stringify({d: palpateViewer.maxDisplacement(), c: palpateViewer.canvasStats(), info: {id: palpateViewer.session.info.sessionId, r: palpateViewer.session.info.radius, e: palpateViewer.session.info.youngModulus, nu: palpateViewer.session.info.poissonRatio}})"));
  check(before.c.drawn > 0.1 && before.c.colours > 8, "the canvas is drawn", `${(100 * before.c.drawn).toFixed(1)} % of pixels, ${before.c.colours} colours`);
  check(before.d < 1e-6, "the surface starts at rest", `largest displacement ${before.d} m`);
  // The scene's stored reference reaches the page (the haptic scene shares the default block's).
  const stored = JSON.parse(readFileSync(join(args.scenes, "references", "hertz_cube.json"), "utf8"));
  const shown = JSON.parse(await page.eval("JSON.stringify({f: Array.from(palpateViewer.session.info.reference.forces), d: Array.from(palpateViewer.session.info.reference.indentation)})"));
  check(JSON.stringify(shown.f) === JSON.stringify(stored.forces) && JSON.stringify(shown.d) === JSON.stringify(stored.indentation),
        "the page has the scene's stored finite-block reference", `${shown.f.length} forces`);

  // 2. Press through the slider's hook.
  const force = 100; // N: d/R ~ 0.08 on the haptic scene
  const eStar = before.info.e / (1 - before.info.nu ** 2);
  const hertzDepth = ((3 * force) / (4 * eStar * Math.sqrt(before.info.r))) ** (2 / 3);
  const framesBefore = await page.eval("palpateViewer.frames");
  await page.eval(`palpateViewer.setForce(${force})`);
  await page.waitFor(`palpateViewer.last && palpateViewer.last.forceCommand === ${force} && palpateViewer.last.indentation > ${0.5 * hertzDepth}`, "the press to show in the frames", 30000);
  await sleep(1500); // let the body settle a little and the page draw
  const after = JSON.parse(await page.eval("JSON.stringify({d: palpateViewer.maxDisplacement(), c: palpateViewer.canvasStats(), frames: palpateViewer.frames, ind: palpateViewer.last.indentation, fz: palpateViewer.last.toolContactForce[2], fieldMax: palpateViewer.fieldMax, bytes: palpateViewer.last.bytes})"));
  check(after.frames - framesBefore >= 20, "frames keep arriving", `${after.frames - framesBefore} frames during the press`);
  check(after.d > 0.1 * hertzDepth, "the tissue surface moved", `largest surface displacement ${after.d.toExponential(3)} m, Hertz depth ${hertzDepth.toExponential(3)} m`);
  check(after.ind > 0.5 * hertzDepth && after.ind < 2 * hertzDepth, "the decoded indentation is a press of that force", `${after.ind.toExponential(4)} m`);
  check(after.fieldMax > 0 && Math.abs(after.fieldMax - after.d) <= 1e-6 * Math.max(after.d, 1e-30) + 1e-7,
        "the displacement field the server computed agrees with the positions", `field max ${after.fieldMax}, |x - X| max ${after.d}`);
  check(after.c.drawn > 0.1, "the canvas is still drawn after the press");
  const png = await page.screenshot();
  writeFileSync(join(args.out, "viewer.png"), png);
  check(png.length > 10000 && png.subarray(1, 4).toString() === "PNG", "a screenshot was taken", `${png.length} bytes in ${join(args.out, "viewer.png")}`);

  // 3. Other tabs on the same session. The opener holds its control token.
  const id = before.info.id;
  const owner = JSON.parse(await page.eval("JSON.stringify({control: palpateViewer.session.info.control, token: palpateViewer.session.controlToken, share: document.getElementById('share').textContent, link: document.querySelector('#control-link a')?.href ?? '', warning: document.getElementById('control-link').textContent, linkHidden: document.getElementById('control-link').hidden})"));
  const token = owner.token;
  check(owner.control === true && /^[0-9a-f]{64}$/.test(token), "the opener controls its session and has its 64-digit control token", `control ${owner.control}`);
  check(owner.share.includes(`?session=${id}`) && !owner.share.includes("token") && !owner.linkHidden && owner.link.endsWith(`?session=${id}&token=${token}`) && owner.warning.includes("share only with whom you would hand the device") && !owner.warning.includes(token),
        "the opener shows the watch link and, apart and with a warning, the control link (token not on screen in full)", `${owner.share} | ${owner.warning}`);

  // 3a. The watch link: a read-only view.
  const watcher = await browser.open(`${server.web}?session=${id}`);
  await watcher.waitFor("window.palpateViewer && palpateViewer.frames >= 5", "a watcher's frames");
  await sleep(500); // a few frames drawn
  const watched = JSON.parse(await watcher.eval("JSON.stringify({id: palpateViewer.session.info.sessionId, control: palpateViewer.session.info.control, token: palpateViewer.session.controlToken, ind: palpateViewer.last.indentation, f: palpateViewer.last.forceCommand, status: document.getElementById('status').textContent, enabled: ['force', 'pause', 'reset', 'step1', 'step100', 'press-depth'].filter((k) => !document.getElementById(k).disabled), share: document.getElementById('share').textContent, controlLink: !document.getElementById('control-link').hidden || document.body.innerHTML.includes('token=')})"));
  check(watched.id === id && watched.f === force && watched.ind > 0.5 * hertzDepth, "a second viewer watches the same session", JSON.stringify({ id: watched.id, f: watched.f, ind: watched.ind }));
  check(watched.control === false && watched.token === "", "the watch link gives a read-only view (info.control false, no token)");
  check(watched.status.includes(`Watching session ${id} read-only`) && watched.enabled.length === 0,
        "the read-only page says so in its status area and disables every command control", `status "${watched.status}", enabled ${JSON.stringify(watched.enabled)}`);
  check(watched.share.includes(`?session=${id}`) && !watched.controlLink, "the read-only page shows the watch link only", watched.share);
  const refused = await watcher.eval("Promise.all([palpateViewer.setForce(1), palpateViewer.step(1)].map((p) => p.then(() => 'sent', (e) => e.message)))");
  check(refused.every((m) => m.includes("read-only")), "the read-only page's setForce and step reject, read-only", JSON.stringify(refused));
  const watcherPng = await watcher.screenshot();
  writeFileSync(join(args.out, "viewer-read-only.png"), watcherPng);
  check(watcherPng.length > 10000, "a screenshot of the read-only page was taken", join(args.out, "viewer-read-only.png"));

  // 3b. The control link: a controller, whose force the opener's frames carry.
  const controller = await browser.open(`${server.web}?session=${id}&token=${token}`);
  await controller.waitFor("window.palpateViewer && palpateViewer.frames >= 2", "the controller's frames");
  const controls = JSON.parse(await controller.eval("JSON.stringify({id: palpateViewer.session.info.sessionId, control: palpateViewer.session.info.control, enabled: !document.getElementById('force').disabled})"));
  check(controls.id === id && controls.control === true && controls.enabled, "the control link gives control (info.control true, the slider enabled)", JSON.stringify(controls));
  const force2 = 60; // N
  await controller.eval(`palpateViewer.setForce(${force2})`);
  const seen = await page.waitFor(`palpateViewer.last.forceCommand === ${force2}`, "the controller's force in the opener's frames", 20000).then(() => true, (e) => e.message);
  const seenByWatcher = await watcher.waitFor(`palpateViewer.last.forceCommand === ${force2}`, "the controller's force in the watcher's frames", 20000).then(() => true, (e) => e.message);
  check(seen === true && seenByWatcher === true, "the controller's setForce reaches the opener's and the watcher's frames", seen === true ? seenByWatcher : seen);

  // 3c. Another field in the opener's tab: the same page and session, frames of the new field
  //     (von Mises, Pa: hundreds where |u| is centimetres). Read from the decoded frames: a
  //     background tab draws nothing (no animation frames), so fieldMax stands still.
  await page.eval("window.notReloaded = true");
  const framesAtSwitch = await page.eval("palpateViewer.frames");
  await page.eval("(() => { const s = document.getElementById('field'); s.value = 'vonMises'; s.dispatchEvent(new Event('change')); })()");
  const switched = await page.waitFor(`palpateViewer.frames > ${framesAtSwitch} + 10 && palpateViewer.last.field !== null && palpateViewer.last.field.reduce((a, b) => Math.max(a, b), 0) > 1`, "frames of the von Mises field", 20000).then(() => true, (e) => e.message);
  const after3 = JSON.parse(await page.eval("JSON.stringify({kept: window.notReloaded === true, id: palpateViewer.session.info.sessionId, field: palpateViewer.field, state: palpateViewer.state, error: palpateViewer.error, search: location.search, fieldMax: palpateViewer.last.field.reduce((a, b) => Math.max(a, b), 0), name: document.getElementById('field-name').textContent})"));
  check(switched === true && after3.kept && after3.id === id && after3.field === "vonMises" && after3.state === "ready" && after3.error === "",
        "changing the field keeps the page, its session and the frames flowing (the new field's)", switched === true ? JSON.stringify(after3) : switched);
  check(after3.search.includes("field=vonMises") && !after3.search.includes("session="), "the address says the field, and still opens a session of its own", after3.search);

  // 3d. The controller leaving keeps the session; the opener leaving ends it, and the
  //     watcher says so.
  await controller.close();
  const watcherFrames = await watcher.eval("palpateViewer.frames");
  const alive = await watcher.waitFor(`palpateViewer.frames > ${watcherFrames} + 10 && palpateViewer.state !== 'ended'`, "frames after the controller left", 20000).then(() => true, (e) => e.message);
  check(alive === true, "the session outlives its controller tab (the opener holds it)", alive === true ? "" : alive);
  await page.close();
  const over = await watcher.waitFor("palpateViewer.state === 'ended'", "the watcher to see the session end", 20000).then(() => true, (e) => e.message);
  const status = await watcher.eval("document.getElementById('status').textContent");
  check(over === true && status.includes(`Session ${id} has ended`), "the opener leaving ends the session, and the watcher says so", over === true ? status : over);
  const errors = [...page.consoleErrors, ...watcher.consoleErrors, ...controller.consoleErrors];
  check(errors.length === 0, "no errors on the pages sharing the session", JSON.stringify(errors));
  await watcher.close();

  // 4. The page's decoding against palpate-client's, for the same headless tick.
  const ticks = 300;
  const headless = await browser.open(`${server.web}?headless=1&scene=${scene}`);
  await headless.waitFor("window.palpateViewer && palpateViewer.state === 'ready'", "the headless session");
  const stepped = JSON.parse(await headless.eval(`(async () => { await palpateViewer.setForce(${force}); const f = await palpateViewer.step(${ticks}); return JSON.stringify({tick: f.tick, ind: f.indentation, z: f.indenterPosition[2], fz: f.toolContactForce[2]}); })()`));
  const csv = join(args.out, "client.csv");
  execFileSync(args.client, ["--connect", server.rpc, "--scene", scene, "--headless", "--forces", String(force), "--max-steps", String(ticks), "--csv", csv], { stdio: ["ignore", "ignore", "inherit"] });
  const [header, row] = readFileSync(csv, "utf8").trim().split("\n");
  const value = Object.fromEntries(header.split(",").map((k, i) => [k, Number(row.split(",")[i])]));
  check(stepped.tick === ticks && value.tick === ticks, "both stepped the same ticks", `page ${stepped.tick}, client ${value.tick}`);
  check(stepped.ind === value.indentation_m, "the page's indentation equals the server's (as palpate-client decodes it) to the bit", `${stepped.ind} vs ${value.indentation_m}`);
  check(stepped.z === value.tool_z_m && stepped.fz === value.contact_fz_n, "and so do the tool's height and contact force", `${stepped.z} / ${value.tool_z_m}, ${stepped.fz} / ${value.contact_fz_n}`);
  check(page.consoleErrors.length === 0 && headless.consoleErrors.length === 0, "no errors on the pages", JSON.stringify([...page.consoleErrors, ...headless.consoleErrors]));

  // 5. A server that asks for an access token (--access-token-file): a page without it is
  //    refused, saying why; with #access=TOKEN it opens a session, and the token leaves the
  //    address bar.
  const accessToken = "a3f1c2e4b5d6978812345678abcdef0123456789abcdef0123456789abcdef01";
  const tokenFile = join(args.out, "access-token");
  writeFileSync(tokenFile, `${accessToken}\n`);
  const guarded = await startServer(args.server, [
    "--scene-dir", args.scenes,
    "--scene", join(args.scenes, `${scene}.json`),
    "--web-root", args["web-root"],
    "--log-level", "error",
    "--access-token-file", tokenFile,
  ]);
  try {
    const stranger = await browser.open(guarded.web);
    await stranger.waitFor("window.palpateViewer && palpateViewer.state === 'error'", "the page without the token to fail");
    const refused = await stranger.eval("palpateViewer.error");
    check(refused.includes("requires an access token"), "without the access token the page is refused, saying why", refused);
    await stranger.close();
    const member = await browser.open(`${guarded.web}#access=${accessToken}`);
    await member.waitFor("window.palpateViewer && palpateViewer.state === 'ready' && palpateViewer.frames >= 5", "frames with the access token");
    const address = await member.eval("location.href");
    check(!address.includes(accessToken) && !address.includes("access="), "with #access=TOKEN the page opens a session, and the token leaves the address bar", address);
    await member.close();
  } finally {
    const status = await stopServer(guarded);
    check(status === 0, "the guarded server exits cleanly on SIGTERM", `status ${status}`);
  }
} catch (error) {
  check(false, "the browser test ran to the end", error.message);
} finally {
  await browser.close();
  const status = await stopServer(server);
  check(status === 0, "the server exits cleanly on SIGTERM", `status ${status}`);
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed === 0 ? 0 : 1);
