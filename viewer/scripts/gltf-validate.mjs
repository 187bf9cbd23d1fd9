// Validate glTF/GLB files with the Khronos glTF-Validator and print one JSON report per file.
//   node scripts/gltf-validate.mjs FILE [FILE...]
// Prints {"file": ..., "report": <validator report>} lines; exit code 1 if any file has errors.
import { readFile } from "node:fs/promises";
import path from "node:path";
import validator from "gltf-validator";

let failed = false;
for (const file of process.argv.slice(2)) {
  const data = new Uint8Array(await readFile(file));
  const report = await validator.validateBytes(data, {
    uri: path.basename(file),
    maxIssues: 100,
    // external resources (none for kesbrdf exports: buffers are embedded)
    externalResourceFunction: (uri) => readFile(path.resolve(path.dirname(file), decodeURIComponent(uri))).then((b) => new Uint8Array(b)),
  });
  if (report.issues.numErrors > 0) failed = true;
  process.stdout.write(JSON.stringify({ file, report }) + "\n");
}
process.exit(failed ? 1 : 0);
