// Validates one glTF file and the files it names with the Khronos glTF validator
// (npm gltf-validator, pinned in package.json); prints the validation report as JSON.
// Usage: node validate_gltf.js FILE.gltf
"use strict";
const fs = require("fs");
const path = require("path");
const validator = require("gltf-validator");

const file = path.resolve(process.argv[2]);
validator
    .validateBytes(new Uint8Array(fs.readFileSync(file)), {
        uri: path.basename(file),
        maxIssues: 0,
        externalResourceFunction: (uri) =>
            fs.promises
                .readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)))
                .then((data) => new Uint8Array(data)),
    })
    .then((report) => console.log(JSON.stringify(report)))
    .catch((error) => {
        console.error(error);
        process.exit(1);
    });
