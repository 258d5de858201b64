#!/usr/bin/env node
// Validate one glTF/GLB file with the Khronos glTF Validator; print the JSON report to stdout.
//
//   node tests/validator/validate.js path/to/scene.glb
//
// External resources (buffers, images) named by relative URI are read from the file's folder.
// Exit status: 0 when a report was produced (whatever its issues), 2 when the validator could
// not run (bad arguments, unreadable file, undetectable format).
"use strict";

const fs = require("fs");
const path = require("path");
const validator = require("gltf-validator");

function main(argv) {
  if (argv.length !== 1) {
    process.stderr.write("usage: node validate.js <file.gltf|file.glb>\n");
    process.exit(2);
  }
  const fullpath = path.resolve(argv[0]);
  const folder = path.dirname(fullpath);
  let bytes;
  try {
    bytes = fs.readFileSync(fullpath);
  } catch (err) {
    process.stderr.write(`cannot read ${fullpath}: ${err.message}\n`);
    process.exit(2);
  }
  const options = {
    uri: path.basename(fullpath),
    maxIssues: 0, // report every issue
    writeTimestamp: false,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        const resource = path.resolve(folder, decodeURIComponent(uri));
        fs.readFile(resource, (err, data) => {
          if (err) {
            reject(err.toString());
            return;
          }
          resolve(new Uint8Array(data));
        });
      }),
  };
  validator.validateBytes(new Uint8Array(bytes), options).then(
    (report) => {
      process.stdout.write(JSON.stringify(report, null, 2) + "\n");
    },
    (error) => {
      process.stderr.write(`glTF validator could not validate ${fullpath}: ${error}\n`);
      process.exit(2);
    }
  );
}

main(process.argv.slice(2));
