// The browser viewer end to end, in a real headless Chromium (ctest viewer_browser_e2e):
//   1. palpate-server --http serves the page; a tab opens a real-time session of the
//      accurate haptic scene and must receive frames and draw (the canvas is not blank);
//   2. the force slider's hook presses the tool: the tissue surface the page draws moves
//      (its largest displacement grows past a tenth of the Hertz depth at that force), the
//      page decodes a positive indentation, and a screenshot is written;
//   3. a second tab watches the same session (?session=ID) and receives frames too;
//   4. a headless session stepped by the page to a tick gives the indentation that
//      palpate-client (C++, TCP) decodes for the same scene, force and tick, to the bit.
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

  // 3. A second viewer of the same session.
  const watcher = await browser.open(`${server.web}?session=${before.info.id}`);
  await watcher.waitFor("window.palpateViewer && palpateViewer.frames >= 5", "a watcher's frames");
  const watched = JSON.parse(await watcher.eval("JSON.stringify({id: palpateViewer.session.info.sessionId, ind: palpateViewer.last.indentation, f: palpateViewer.last.forceCommand})"));
  check(watched.id === before.info.id && watched.f === force && watched.ind > 0.5 * hertzDepth, "a second viewer watches the same session", JSON.stringify(watched));
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
} catch (error) {
  check(false, "the browser test ran to the end", error.message);
} finally {
  await browser.close();
  const status = await stopServer(server);
  check(status === 0, "the server exits cleanly on SIGTERM", `status ${status}`);
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed === 0 ? 0 : 1);
