// Validates a .glb with the Khronos glTF validator (viewer/node_modules) and prints its report as
// JSON on stdout: node tests/gltf_validate.mjs FILE.glb
import { readFileSync } from "node:fs";
import { createRequire } from "node:module";
import { fileURLToPath } from "node:url";

const require = createRequire(fileURLToPath(new URL("../viewer/package.json", import.meta.url)));
const validator = require("gltf-validator");
const file = process.argv[2];
const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), { uri: file, maxIssues: 100 });
process.stdout.write(JSON.stringify(report));
