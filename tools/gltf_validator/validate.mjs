// Validate one .glb with the Khronos glTF validator; print its issue counts and the
// errors and warnings as JSON on one line. Usage: node validate.mjs FILE.glb
import { readFileSync } from 'node:fs';
import validator from 'gltf-validator';

const path = process.argv[2];
const report = await validator.validateBytes(new Uint8Array(readFileSync(path)), {
  uri: path,
  externalResourceFunction: (uri) => Promise.reject(new Error(`external resource ${uri}`)),
});
const issues = report.issues;
console.log(JSON.stringify({
  errors: issues.numErrors,
  warnings: issues.numWarnings,
  messages: issues.messages
    .filter((m) => m.severity <= 1)
    .map((m) => `${m.code} ${m.pointer ?? ''}: ${m.message}`),
}));
