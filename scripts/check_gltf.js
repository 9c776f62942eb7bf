// Checks a .gltf/.glb with the Khronos glTF validator and decodes every KHR_draco_mesh_compression primitive
// with draco3d. Prints one JSON object:
//   {errors, warnings, messages: [first errors/warnings], draco: [{mesh, primitive, points, faces, attributes}]}
// Tools come from scripts/setup_test_tools.sh (RAYSPLATS_NPM_DIR, default ~/.cache/raysplats/npm).
//   node scripts/check_gltf.js FILE
'use strict';
const fs = require('fs');
const os = require('os');
const path = require('path');

const npmDir = process.env.RAYSPLATS_NPM_DIR || path.join(os.homedir(), '.cache', 'raysplats', 'npm');
const validator = require(path.join(npmDir, 'node_modules', 'gltf-validator'));
const draco3d = require(path.join(npmDir, 'node_modules', 'draco3d'));

function parseContainer(bytes) {
  // Returns {json, bin} for a .glb, or {json, bin: null} for a .gltf (buffers resolved by uri).
  if (bytes.readUInt32LE(0) === 0x46546c67) {  // "glTF"
    const jsonLength = bytes.readUInt32LE(12);
    const json = JSON.parse(bytes.subarray(20, 20 + jsonLength).toString('utf8'));
    const binStart = 20 + jsonLength;
    const bin = binStart + 8 <= bytes.length ? bytes.subarray(binStart + 8, binStart + 8 + bytes.readUInt32LE(binStart)) : null;
    return {json, bin};
  }
  return {json: JSON.parse(bytes.toString('utf8')), bin: null};
}

async function main() {
  const file = process.argv[2];
  const bytes = fs.readFileSync(file);
  const dir = path.dirname(file);
  const report = await validator.validateBytes(new Uint8Array(bytes), {
    uri: path.basename(file),
    maxIssues: 100,
    externalResourceFunction: (uri) => new Promise((resolve, reject) => {
      fs.readFile(path.join(dir, decodeURIComponent(uri)), (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
    }),
  });
  const messages = report.issues.messages
    .filter((m) => m.severity <= 1)
    .slice(0, 20)
    .map((m) => `${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer || ''}: ${m.message}`);

  const {json, bin} = parseContainer(bytes);
  const buffers = (json.buffers || []).map((b, i) => (b.uri ? fs.readFileSync(path.join(dir, decodeURIComponent(b.uri))) : (i === 0 ? bin : null)));
  const draco = [];
  const decoderModule = await draco3d.createDecoderModule({});
  (json.meshes || []).forEach((mesh, m) => {
    mesh.primitives.forEach((prim, p) => {
      const ext = prim.extensions && prim.extensions.KHR_draco_mesh_compression;
      if (!ext) return;
      const view = json.bufferViews[ext.bufferView];
      const data = buffers[view.buffer].subarray(view.byteOffset || 0, (view.byteOffset || 0) + view.byteLength);
      const decoder = new decoderModule.Decoder();
      const dmesh = new decoderModule.Mesh();
      const status = decoder.DecodeArrayToMesh(new Int8Array(data.buffer, data.byteOffset, data.byteLength), data.byteLength, dmesh);
      const attributes = {};
      for (const [name, id] of Object.entries(ext.attributes)) {
        const attribute = decoder.GetAttributeByUniqueId(dmesh, id);
        attributes[name] = attribute && attribute.ptr ? attribute.num_components() : 0;
      }
      draco.push({mesh: m, primitive: p, ok: status.ok(), error: status.ok() ? '' : status.error_msg(),
                  points: dmesh.num_points(), faces: dmesh.num_faces(), attributes,
                  accessor_points: json.accessors[prim.attributes.POSITION].count,
                  accessor_faces: json.accessors[prim.indices].count / 3});
      decoderModule.destroy(dmesh);
      decoderModule.destroy(decoder);
    });
  });
  console.log(JSON.stringify({errors: report.issues.numErrors, warnings: report.issues.numWarnings, messages, draco}));
}

main().catch((e) => {
  console.error(`check_gltf: ${e && e.stack ? e.stack : e}`);
  process.exit(2);
});
