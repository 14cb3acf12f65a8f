// Validates a glTF or GLB file with the Khronos glTF validator
// (npm gltf-validator) and prints its report's issues as JSON:
// node tests/gltf/validate.mjs FILE
import { readFileSync } from "node:fs";
import { basename } from "node:path";
import validator from "gltf-validator";

const file = process.argv[2];
const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
  uri: basename(file),
  maxIssues: 0,
});
console.log(JSON.stringify({ validatorVersion: report.validatorVersion, issues: report.issues, info: report.info }));
