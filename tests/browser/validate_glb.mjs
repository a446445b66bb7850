// The Khronos glTF validator (npm gltf-validator, pinned in package-lock.json)
// over .glb files, run by run.sh. Prints the report's counts and every
// message; exits 1 if any file has an error or a warning (infos and hints
// are printed, not failed).
//
//   node validate_glb.mjs FILE.glb [FILE.glb ...]
import validator from "gltf-validator";
import { readFileSync, statSync } from "node:fs";

const files = process.argv.slice(2);
if (files.length === 0) { console.error("usage: node validate_glb.mjs FILE.glb [...]"); process.exit(2); }
let failed = 0;
for (const f of files) {
  const r = await validator.validateBytes(new Uint8Array(readFileSync(f)), { maxIssues: 0 });
  const i = r.issues;
  const ok = i.numErrors === 0 && i.numWarnings === 0;
  console.log(`${ok ? "PASS" : "FAIL"}  gltf-validator ${r.validatorVersion}: ${f} (${statSync(f).size} bytes): ` +
    `${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ${i.numHints} hints`);
  for (const m of i.messages) console.log(`      ${["error", "warning", "info", "hint"][m.severity]} ${m.code} ${m.pointer || ""}: ${m.message}`);
  if (!ok) failed++;
}
process.exit(failed === 0 ? 0 : 1);
