// A headless Chromium driven over the DevTools protocol on a pipe (--remote-debugging-pipe:
// JSON messages ending in NUL, written to the browser's fd 3 and read from its fd 4), and a
// palpate-server started for the test. Node's standard library only: the browser test and
// the viewer benchmark need no npm packages of their own.
import { spawn } from "node:child_process";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

export class Browser {
  static launch(executable = process.env.CHROMIUM ?? "chromium", { width = 1280, height = 800 } = {}) {
    const profile = mkdtempSync(join(tmpdir(), "palpate-chromium-"));
    const args = [
      "--headless=new",
      "--no-sandbox", // the suite runs as root in CI
      "--remote-debugging-pipe",
      // WebGL without a GPU: ANGLE on SwiftShader (software)
      "--use-angle=swiftshader",
      "--enable-unsafe-swiftshader",
      "--no-first-run",
      "--no-default-browser-check",
      "--disable-extensions",
      "--disable-background-networking",
      "--disable-background-timer-throttling",
      "--disable-renderer-backgrounding",
      "--disable-backgrounding-occluded-windows",
      `--user-data-dir=${profile}`,
      `--window-size=${width},${height}`,
      "about:blank",
    ];
    const child = spawn(executable, args, { stdio: ["ignore", "ignore", "pipe", "pipe", "pipe"] });
    let log = "";
    child.stderr.on("data", (d) => (log = (log + d).slice(-20000)));
    return new Browser(child, profile, () => log);
  }

  constructor(child, profile, log) {
    this.child = child;
    this.profile = profile;
    this.log = log;
    this.nextId = 1;
    this.pending = new Map();
    this.listeners = [];
    this.exited = new Promise((resolve) => child.on("exit", (code, signal) => resolve({ code, signal })));
    this.exited.then(({ code, signal }) => {
      for (const { reject } of this.pending.values())
        reject(new Error(`chromium exited (${code ?? signal}) before answering:\n${this.log()}`));
      this.pending.clear();
    });
    let buffer = Buffer.alloc(0);
    child.stdio[4].on("data", (chunk) => {
      buffer = Buffer.concat([buffer, chunk]);
      let end;
      while ((end = buffer.indexOf(0)) >= 0) {
        const message = JSON.parse(buffer.subarray(0, end).toString("utf8"));
        buffer = buffer.subarray(end + 1);
        if (message.id !== undefined && this.pending.has(message.id)) {
          const { resolve, reject, method } = this.pending.get(message.id);
          this.pending.delete(message.id);
          if (message.error) reject(new Error(`${method}: ${message.error.message}`));
          else resolve(message.result);
        } else {
          for (const l of this.listeners) l(message);
        }
      }
    });
  }

  send(method, params = {}, sessionId = undefined) {
    const id = this.nextId++;
    const message = { id, method, params };
    if (sessionId) message.sessionId = sessionId;
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject, method });
      this.child.stdio[3].write(JSON.stringify(message) + "\0");
    });
  }

  // A new tab at `url`; returns a Page.
  async open(url) {
    const { targetId } = await this.send("Target.createTarget", { url: "about:blank" });
    const { sessionId } = await this.send("Target.attachToTarget", { targetId, flatten: true });
    const page = new Page(this, sessionId, targetId);
    await page.send("Page.enable");
    await page.send("Runtime.enable");
    page.consoleErrors = [];
    this.listeners.push((m) => {
      if (m.sessionId !== sessionId) return;
      if (m.method === "Runtime.exceptionThrown") page.consoleErrors.push(m.params.exceptionDetails.text + " " + (m.params.exceptionDetails.exception?.description ?? ""));
      if (m.method === "Runtime.consoleAPICalled" && m.params.type === "error")
        page.consoleErrors.push(m.params.args.map((a) => a.value ?? a.description).join(" "));
    });
    await page.send("Page.navigate", { url });
    return page;
  }

  async close() {
    try {
      await Promise.race([this.send("Browser.close"), sleep(3000)]);
    } catch {
      // already gone
    }
    if (this.child.exitCode === null) this.child.kill("SIGKILL");
    await Promise.race([this.exited, sleep(3000)]);
    // Chromium's helper processes may still be writing the profile for a moment.
    try {
      rmSync(this.profile, { recursive: true, force: true, maxRetries: 10, retryDelay: 200 });
    } catch (error) {
      console.log(`note: the browser profile ${this.profile} was not removed: ${error.message}`);
    }
  }
}

export class Page {
  constructor(browser, sessionId, targetId) {
    this.browser = browser;
    this.sessionId = sessionId;
    this.targetId = targetId;
  }
  send(method, params = {}) {
    return this.browser.send(method, params, this.sessionId);
  }
  // Evaluates an expression (awaiting a promise) and returns its value as JSON.
  async eval(expression) {
    const r = await this.send("Runtime.evaluate", { expression, awaitPromise: true, returnByValue: true });
    if (r.exceptionDetails)
      throw new Error(`${expression}: ${r.exceptionDetails.exception?.description ?? r.exceptionDetails.text}`);
    return r.result.value;
  }
  // Polls `expression` until it is truthy; fails after timeoutMs with `what` and the page's state.
  async waitFor(expression, what, timeoutMs = 60000) {
    const start = Date.now();
    for (;;) {
      let value;
      try {
        value = await this.eval(expression);
      } catch {
        value = undefined; // e.g. the page is still loading
      }
      if (value) return value;
      if (Date.now() - start > timeoutMs) {
        const state = await this.eval("JSON.stringify(window.palpateViewer ? {state: palpateViewer.state, error: palpateViewer.error, frames: palpateViewer.frames} : 'no viewer')").catch((e) => String(e));
        throw new Error(`timed out after ${timeoutMs} ms waiting for ${what}; viewer: ${state}; page errors: ${JSON.stringify(this.consoleErrors)}`);
      }
      await sleep(100);
    }
  }
  async screenshot() {
    const { data } = await this.send("Page.captureScreenshot", { format: "png" });
    return Buffer.from(data, "base64");
  }
  async close() {
    await this.browser.send("Target.closeTarget", { targetId: this.targetId });
  }
}

// palpate-server on free ports; resolves with {rpc: "127.0.0.1:P", web: "http://127.0.0.1:Q/"}.
export function startServer(executable, args) {
  const child = spawn(executable, ["--listen", "127.0.0.1:0", "--http", "127.0.0.1:0", ...args], {
    stdio: ["ignore", "pipe", "pipe"],
  });
  let out = "";
  let err = "";
  child.stderr.on("data", (d) => (err = (err + d).slice(-20000)));
  const ready = new Promise((resolve, reject) => {
    child.stdout.on("data", (d) => {
      out += d;
      const rpc = /listening on (\S+)/.exec(out);
      const web = /web on (\S+)/.exec(out);
      if (rpc && web) resolve({ child, rpc: rpc[1], web: web[1], stderr: () => err });
    });
    child.on("exit", (code) => reject(new Error(`palpate-server exited with ${code}: ${err}`)));
  });
  return ready;
}

export async function stopServer(server) {
  if (server.child.exitCode !== null) return server.child.exitCode;
  const exited = new Promise((resolve) => server.child.on("exit", (code) => resolve(code)));
  server.child.kill("SIGTERM");
  const code = await Promise.race([exited, sleep(10000).then(() => "timeout")]);
  if (code === "timeout") server.child.kill("SIGKILL");
  return code;
}
