// Validate a glTF file with the Khronos validator (npm `gltf-validator`, FORMATS.md §2.8).
// Usage: node tests/gltf_validate.js file.glb  ->  the JSON report on stdout;
// exit code 0 without errors, 1 with errors, 2 when the file cannot be validated at all.
// The module is found through NODE_PATH (tests/test_gltf_export.py installs it into a cache
// folder). exitCode rather than process.exit(), so a long report is never cut off a pipe.
const fs = require('fs'), v = require('gltf-validator');
v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])),
                {uri: process.argv[2], maxIssues: 0, writeTimestamp: false})
 .then(r => { console.log(JSON.stringify(r)); process.exitCode = r.issues.numErrors ? 1 : 0; },
       e => { console.error(String(e)); process.exitCode = 2; });
