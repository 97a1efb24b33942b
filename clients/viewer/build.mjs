// Builds the browser viewer into one folder the server serves (palpate-server --web-root).
//
//   node build.mjs --schema protocol/palpate.capnp --modules DIR/node_modules --out DIR/viewer
//
// 1. The schema's TypeScript from capnp-es's compiler (capnp compile -o capnpc-ts). capnp-es
//    0.0.16 emits, for any `-> stream` method, an import of "capnp-es/capnp/stream", a module
//    the package does not ship, beside its own StreamResult class: the import is removed
//    (the generated file defines StreamResult itself) and the result bundled as TypeScript.
// 2. esbuild bundles src/main.ts with three.js and capnp-es into viewer.js (no type checking:
//    esbuild strips the types); index.html and viewer.css are copied beside it.
// Nothing is fetched at page load: the folder is self-contained.
import { execFileSync } from "node:child_process";
import { copyFileSync, mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { dirname, join, resolve } from "node:path";
import { fileURLToPath, pathToFileURL } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const args = Object.fromEntries(
  process.argv.slice(2).reduce((pairs, a, i, all) => (a.startsWith("--") ? [...pairs, [a.slice(2), all[i + 1]]] : pairs), []),
);
for (const key of ["schema", "modules", "out"]) {
  if (!args[key]) {
    console.error(`build.mjs: --${key} is required (usage: node build.mjs --schema FILE --modules DIR --out DIR)`);
    process.exit(2);
  }
}
const schema = resolve(args.schema);
const modules = resolve(args.modules);
const out = resolve(args.out);
const generated = join(out, "..", "viewer-schema");
mkdirSync(out, { recursive: true });
mkdirSync(generated, { recursive: true });

execFileSync(
  "capnp",
  ["compile", "-I/usr/include", `-o${join(modules, ".bin", "capnpc-ts")}:${generated}`, `--src-prefix=${dirname(schema)}`, schema],
  { stdio: ["ignore", "ignore", "inherit"] },
);
const schemaTs = join(generated, "palpate.ts");
const text = readFileSync(schemaTs, "utf8");
const streamImport = /^import \{ StreamResult \} from "capnp-es\/capnp\/stream";\n/m;
if (!streamImport.test(text)) {
  console.error("build.mjs: capnp-es no longer emits the stream import this script removes: check the workaround");
  process.exit(1);
}
writeFileSync(schemaTs, text.replace(streamImport, ""));

const esbuild = await import(pathToFileURL(join(modules, "esbuild", "lib", "main.js")).href);
await esbuild.build({
  entryPoints: [join(here, "src", "main.ts")],
  bundle: true,
  format: "esm",
  target: "es2022",
  minify: true,
  sourcemap: true,
  outfile: join(out, "viewer.js"),
  nodePaths: [modules],
  alias: { "palpate-schema": schemaTs },
  logLevel: "warning",
});
for (const file of ["index.html", "viewer.css"]) copyFileSync(join(here, "src", file), join(out, file));
console.log(`viewer built in ${out}`);
