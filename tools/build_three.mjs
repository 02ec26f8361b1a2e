// Builds omaps/report/assets/three.min.js: the three.js names listed in
// omaps/report/assets/three-entry.js (and OrbitControls) bundled by esbuild into one minified
// classic script that defines the global THREE, with three.js's license comment at its end.
// three and esbuild are the exact versions pinned in tools/package.json; the same versions and
// options give the same bytes on any machine (tests/test_three_bundle.py checks the committed file).
// Usage: node tools/build_three.mjs [OUTFILE]   (after `npm ci --prefix tools`;
//        OUTFILE defaults to omaps/report/assets/three.min.js)
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";
import { fileURLToPath } from "node:url";

const tools = path.dirname(fileURLToPath(import.meta.url));
const root = path.dirname(tools);
const require = createRequire(import.meta.url);

// the installed packages must be the pinned ones (a stale tools/node_modules builds other bytes)
const pins = JSON.parse(fs.readFileSync(path.join(tools, "package.json"), "utf8")).dependencies;
for (const name of ["three", "esbuild"]) {
  let installed;
  try {
    installed = JSON.parse(fs.readFileSync(path.join(tools, "node_modules", name, "package.json"), "utf8")).version;
  } catch {
    console.error(`build_three: ${name} is not installed in tools/node_modules (run \`npm ci --prefix tools\`)`);
    process.exit(2);
  }
  if (installed !== pins[name]) {
    console.error(`build_three: tools/node_modules has ${name} ${installed}, tools/package.json pins ` +
      `${pins[name]} (run \`npm ci --prefix tools\`)`);
    process.exit(2);
  }
}

const esbuild = require("esbuild");
const outfile = path.resolve(process.argv[2] ?? path.join(root, "omaps", "report", "assets", "three.min.js"));

await esbuild.build({
  absWorkingDir: root,
  entryPoints: [path.join(root, "omaps", "report", "assets", "three-entry.js")],
  nodePaths: [path.join(tools, "node_modules")],
  bundle: true,
  minify: true,
  format: "iife",
  globalName: "THREE",
  platform: "browser",
  legalComments: "eof",
  outfile,
  logLevel: "warning",
});
