// Khronos glTF-Validator (npm gltf-validator, pinned in tools/package.json) on one or more
// .glb / .gltf files: prints one JSON object per file (the validator's issue counts, and every
// message of severity error or warning) and exits 1 when any file has an error.
// Usage: node tools/validate_gltf.mjs FILE...   (after `npm ci --prefix tools`)
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const validator = require("gltf-validator");

let failed = false;
for (const file of process.argv.slice(2)) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  });
  const issues = report.issues;
  const out = {
    file,
    validatorVersion: report.validatorVersion,
    numErrors: issues.numErrors,
    numWarnings: issues.numWarnings,
    numInfos: issues.numInfos,
    numHints: issues.numHints,
    messages: issues.messages.filter((m) => m.severity <= 1)
      .map((m) => ({ code: m.code, severity: m.severity, message: m.message, pointer: m.pointer })),
    infoCodes: [...new Set(issues.messages.filter((m) => m.severity >= 2).map((m) => m.code))],
    unused: issues.messages.filter((m) => m.code === "UNUSED_OBJECT").map((m) => m.pointer),
  };
  if (issues.numErrors > 0) failed = true;
  console.log(JSON.stringify(out));
}
process.exit(failed ? 1 : 0);
