// Runs the Khronos glTF validator (npm gltf-validator) on one file: prints every issue and exits
// 1 when it reports an error (or cannot read the file), 0 otherwise.
'use strict';
const fs = require('fs');
const path = require('path');

const [validatorDir, file] = process.argv.slice(2);
const validator = require(path.join(validatorDir, 'node_modules', 'gltf-validator'));

validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {uri: path.basename(file)})
    .then((report) => {
        const i = report.issues;
        for (const m of i.messages) {
            const level = ['error', 'warning', 'info', 'hint'][m.severity] || m.severity;
            console.log(`${level}: ${m.code} ${m.pointer || ''}: ${m.message}`);
        }
        console.log(`gltf-validator ${validator.version()}: ${file}: ${i.numErrors} errors, ` +
                    `${i.numWarnings} warnings, ${i.numInfos} infos, ${i.numHints} hints`);
        process.exit(i.numErrors === 0 ? 0 : 1);
    }, (failure) => {
        console.log(`gltf-validator could not read ${file}: ${failure}`);
        process.exit(1);
    });
