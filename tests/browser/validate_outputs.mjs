#!/usr/bin/env node
// validate_outputs.mjs: runs the Khronos glTF-Validator (npm gltf-validator) on every output
// glTF and .glb that bake_scenes.mjs wrote, with its external resources loaded from the
// output folder only (a URI that leaves the folder is an error: outputs are self-contained),
// and asserts no error and no warning. Infos and hints are printed, counted by code.
//
// The validator does not know MX_lightmap, so it reports every TEXCOORD_1 as unused
// (MESH_PRIMITIVE_UNUSED_TEXCOORD, info) and the lightmap textures as unused objects
// (UNUSED_OBJECT); this script checks the extension itself instead (exact identities):
//   - every primitive that has TEXCOORD_1 belongs to a mesh that a node with
//     MX_lightmap.lightMapTexture.texCoord = 1 uses (no TEXCOORD_1 is left unused), and
//     every such node's primitives have TEXCOORD_1;
//   - per node, scale and offset are the manifest's scaleOffset (identity in the --atlas-uv
//     bake, whose TEXCOORD_1 holds the transform), the texture's image is the
//     manifest page's LDR PNG (image/png), intensity is 2 pi (dldr) or pi (rgbm), the sampler
//     is LINEAR / LINEAR (no mipmaps) / CLAMP_TO_EDGE, and extras.kiln.page is the node's
//     lightmapIndex;
//   - every node the manifest lightmaps has the extension, and no other node has it;
//   - every node the manifest marks probeLit has extras.kiln.probeSH, the manifest's 27
//     numbers, and no other node has one;
//   - KHR_lights_punctual lights: extras.kiln.baked is true exactly for the lights whose
//     direct light the bake holds (manifest lights[].bakedDirect).
//
// With --shared DIR (the bakes of bake_scenes.mjs --shared) it validates each real scene's
// input glTF too: a warning that the input has as well (same code, same JSON pointer: the
// breakfast room's DDS images, mimeType image/vnd-ms.dds for MSFT_texture_dds) is the
// input's, passed through as it is; it is printed and counted, and does not fail the test.
//
//   node tests/browser/validate_outputs.mjs --bakes DIR [--shared DIR]
// Exit: 0 pass, 1 fail, 77 skipped (gltf-validator not installed; not under CI=true).
import { readdirSync, readFileSync, realpathSync, statSync } from 'node:fs';
import { basename, dirname, join, resolve, sep } from 'node:path';
import { ATLAS_UV_SUFFIX, parseArgs, readJson, requireWebPackage, selectScenes } from './common.mjs';

const args = parseArgs(process.argv.slice(2), ['bakes'], 'validate_outputs.mjs --bakes DIR [--shared DIR]');
// Bake folder name -> input glTF, for the real scenes (their input warnings are allowed).
const inputs = new Map(args.shared === undefined ? []
                                                 : selectScenes(args).list.map((s) => [s.name, s.path]));
const validator = requireWebPackage('gltf-validator');

const LINEAR = 9729, CLAMP_TO_EDGE = 33071;
const SEVERITY = ['error', 'warning', 'info', 'hint'];

function readGlbJson(bytes) {
  if (bytes.readUInt32LE(0) !== 0x46546c67) throw new Error('not a GLB (bad magic)');
  const length = bytes.readUInt32LE(12);
  if (bytes.readUInt32LE(16) !== 0x4e4f534a) throw new Error('the first GLB chunk is not JSON');
  return JSON.parse(bytes.subarray(20, 20 + length).toString('utf8'));
}

// Own checks of the kiln extension; returns a list of failure messages.
function checkLightmaps(file, json, manifest, atlasUv) {
  const failures = [];
  const where = (s) => `${file}: ${s}`;
  const nodes = json.nodes || [], meshes = json.meshes || [];
  const lightmapUsers = new Map();  // mesh index -> nodes with MX_lightmap texCoord 1
  const byNode = new Map((manifest.objects || []).map((o) => [o.nodeIndex, o]));
  const pages = new Map((manifest.lightmaps || []).map((p) => [p.index, p]));
  const used = (json.extensionsUsed || []).includes('MX_lightmap');
  let count = 0;
  nodes.forEach((node, n) => {
    const ext = node.extensions && node.extensions.MX_lightmap;
    const object = byNode.get(n);
    const lightmapped = object && object.lightmapIndex >= 0;
    const sh = node.extras && node.extras.kiln && node.extras.kiln.probeSH;
    if (object && object.probeLit) {
      if (JSON.stringify(sh) !== JSON.stringify(object.probeSH) || !Array.isArray(sh) || sh.length !== 27)
        failures.push(where(`nodes[${n}] ("${node.name}").extras.kiln.probeSH: ${JSON.stringify(sh)}, ` +
                            `the manifest's probeSH is ${JSON.stringify(object.probeSH)}`));
    } else if (sh !== undefined) {
      failures.push(where(`nodes[${n}] ("${node.name}").extras.kiln.probeSH: the manifest does not mark the node probeLit`));
    }
    if (!ext) {
      if (lightmapped) failures.push(where(`nodes[${n}] ("${node.name}"): the manifest gives it lightmap ${object.lightmapIndex} but it has no MX_lightmap`));
      return;
    }
    ++count;
    const at = `nodes[${n}] ("${node.name}").extensions.MX_lightmap`;
    if (!lightmapped) {
      failures.push(where(`${at}: the manifest has no lightmap for this node`));
      return;
    }
    if (node.mesh === undefined) failures.push(where(`${at}: the node has no mesh`));
    const t = ext.lightMapTexture || {};
    if (t.texCoord !== 1) failures.push(where(`${at}.lightMapTexture.texCoord: ${t.texCoord}, expected 1`));
    else if (node.mesh !== undefined) {
      if (!lightmapUsers.has(node.mesh)) lightmapUsers.set(node.mesh, []);
      lightmapUsers.get(node.mesh).push(n);
    }
    // --atlas-uv outputs hold the transform in TEXCOORD_1: identity here.
    const so = atlasUv ? [1, 1, 0, 0] : object.scaleOffset;
    if (JSON.stringify(ext.scale) !== JSON.stringify(so.slice(0, 2)) ||
        JSON.stringify(ext.offset) !== JSON.stringify(so.slice(2, 4)))
      failures.push(where(`${at}: scale ${JSON.stringify(ext.scale)} / offset ${JSON.stringify(ext.offset)}, the manifest's scaleOffset is ${JSON.stringify(so)}`));
    const kiln = (ext.extras && ext.extras.kiln) || {};
    if (kiln.page !== object.lightmapIndex)
      failures.push(where(`${at}.extras.kiln.page: ${kiln.page}, the manifest's lightmapIndex is ${object.lightmapIndex}`));
    const expectedIntensity = { dldr: 2 * Math.PI, rgbm: Math.PI }[kiln.encoding];
    const expectedRange = { dldr: 2, rgbm: 8 }[kiln.encoding];
    if (expectedIntensity === undefined)
      failures.push(where(`${at}.extras.kiln.encoding: "${kiln.encoding}", expected dldr or rgbm`));
    else {
      if (Math.abs(ext.intensity - expectedIntensity) > 1e-6 * expectedIntensity)
        failures.push(where(`${at}.intensity: ${ext.intensity}, expected ${expectedIntensity} for ${kiln.encoding}`));
      if (kiln.range !== expectedRange)
        failures.push(where(`${at}.extras.kiln.range: ${kiln.range}, expected ${expectedRange} for ${kiln.encoding}`));
    }
    const texture = (json.textures || [])[t.index];
    if (!texture) {
      failures.push(where(`${at}.lightMapTexture.index: ${t.index} is not a texture`));
      return;
    }
    const image = (json.images || [])[texture.source];
    const page = pages.get(object.lightmapIndex);
    const ldrFile = page && page.files && page.files.lightLdr;
    if (!image || image.mimeType !== 'image/png')
      failures.push(where(`textures[${t.index}].source: expected a PNG image (mimeType image/png)`));
    else if (image.uri !== undefined && ldrFile !== undefined && image.uri !== ldrFile)
      failures.push(where(`images[${texture.source}].uri: "${image.uri}", the manifest's page ${object.lightmapIndex} LDR file is "${ldrFile}"`));
    else if (image.uri !== undefined && kiln.encoding && !image.uri.endsWith(`_${kiln.encoding}.png`))
      failures.push(where(`images[${texture.source}].uri: "${image.uri}" is not a _${kiln.encoding}.png page`));
    const sampler = (json.samplers || [])[texture.sampler];
    if (!sampler || sampler.magFilter !== LINEAR || sampler.minFilter !== LINEAR ||
        (sampler.wrapS ?? 10497) !== CLAMP_TO_EDGE || (sampler.wrapT ?? 10497) !== CLAMP_TO_EDGE)
      failures.push(where(`textures[${t.index}].sampler: expected LINEAR/LINEAR filters and CLAMP_TO_EDGE, got ${JSON.stringify(sampler)}`));
  });
  if (count > 0 && !used) failures.push(where('extensionsUsed: MX_lightmap is missing'));
  if (count === 0) failures.push(where('no node has MX_lightmap'));

  // TEXCOORD_1 only where a lightmap uses it, and everywhere one does.
  const passedThrough = [];
  meshes.forEach((mesh, m) => {
    const users = lightmapUsers.get(m);
    mesh.primitives.forEach((p, i) => {
      const has = p.attributes && p.attributes.TEXCOORD_1 !== undefined;
      if (has && !users) {
        // Allowed only as the input's own data passed through: a mesh that only objects
        // without a lightmap use (dynamic or scaleInLightmap 0: kiln leaves their authored
        // TEXCOORD_1 alone), or that no node uses (an original kept beside its rebuilt copy).
        const referencedBy = nodes.map((nd, n) => (nd.mesh === m ? n : null)).filter((n) => n !== null);
        const lightmapped = referencedBy.filter((n) => (byNode.get(n) || {}).lightmapIndex >= 0);
        if (lightmapped.length > 0)
          failures.push(where(`meshes[${m}] ("${mesh.name}").primitives[${i}].attributes.TEXCOORD_1: ` +
                              `lightmapped nodes ${lightmapped.join(', ')} use this mesh without MX_lightmap (texCoord 1)`));
        else
          passedThrough.push(`meshes[${m}] ("${mesh.name}").primitives[${i}] (nodes: ${referencedBy.join(', ') || 'none'})`);
      }
      if (!has && users)
        failures.push(where(`meshes[${m}] ("${mesh.name}").primitives[${i}]: no TEXCOORD_1, but nodes ${users.join(', ')} lightmap it through texCoord 1`));
    });
  });

  if (passedThrough.length > 0)
    console.log(`  ${file}: TEXCOORD_1 passed through from the input, no lightmap: ${passedThrough.join('; ')}`);

  // Baked lights.
  const lights = (json.extensions && json.extensions.KHR_lights_punctual &&
                  json.extensions.KHR_lights_punctual.lights) || [];
  const bakes = manifest.lights || [];
  lights.forEach((light, l) => {
    const entry = bakes.find((b) => b.lightIndex === l);
    const baked = light.extras && light.extras.kiln && light.extras.kiln.baked;
    const expected = entry ? entry.bakedDirect === true : undefined;
    if (expected === undefined) failures.push(where(`KHR_lights_punctual.lights[${l}]: not in the manifest's lights`));
    else if (baked !== expected)
      failures.push(where(`KHR_lights_punctual.lights[${l}] ("${light.name}").extras.kiln.baked: ${baked}, expected ${expected} (manifest bakedDirect)`));
  });
  return failures;
}

// What the messages of one code point at, counted: "TEXCOORD_1 x 16, /textures x 1".
function describePointers(list) {
  const kinds = new Map();
  for (const m of list) {
    const p = m.pointer || '';
    const attribute = /\/attributes\/(\w+)$/.exec(p);
    const kind = attribute ? attribute[1] : p.replace(/\/\d+.*$/, '') || '(document)';
    kinds.set(kind, (kinds.get(kind) || 0) + 1);
  }
  return [...kinds].map(([k, v]) => `${k} x ${v}`).join(', ');
}

// The validator's report on one file, external resources read from `dir` only (the URIs
// that resolve outside it are returned in `outside`).
async function validate(file, dir, bytes) {
  const root = realpathSync(dir);
  const outside = [];
  const report = await validator.validateBytes(new Uint8Array(bytes), {
    uri: file,
    maxIssues: 0,
    writeTimestamp: false,
    externalResourceFunction: (uri) => new Promise((resolveData, reject) => {
      let path;
      try {
        path = realpathSync(resolve(dir, decodeURIComponent(uri)));
      } catch (e) {
        reject(`${uri}: ${e.message}`);
        return;
      }
      if (path !== root && !path.startsWith(root + sep)) {
        outside.push(uri);
        reject(`${uri} resolves outside the output folder ${dir}`);
        return;
      }
      resolveData(new Uint8Array(readFileSync(path)));
    }),
  });
  return { report, outside };
}

const t0 = performance.now();
const outputs = [];
for (const entry of readdirSync(args.bakes).sort()) {
  const dir = join(args.bakes, entry);
  if (!statSync(dir).isDirectory()) continue;
  for (const f of readdirSync(dir).sort())
    if (f.endsWith('.gltf') || f.endsWith('.glb')) outputs.push({ dir, file: join(dir, f) });
}
if (outputs.length === 0) {
  console.error(`FAILED: no .gltf or .glb in ${args.bakes}/*/: run tests/browser/bake_scenes.mjs first ` +
                '(the CTest fixture browser_bakes does)');
  process.exit(1);
}

let failures = 0;
const infoTotals = new Map();
for (const { dir, file } of outputs) {
  const bytes = readFileSync(file);
  const { report, outside } = await validate(file, dir, bytes);
  const issues = report.issues;
  const byCode = new Map();
  for (const m of issues.messages) {
    const key = `${SEVERITY[m.severity]} ${m.code}`;
    if (!byCode.has(key)) byCode.set(key, []);
    byCode.get(key).push(m);
  }
  // Warnings of a real scene's input, at the same place in the output: the input's.
  const input = inputs.get(basename(dir));
  const inputWarnings = new Set();
  if (input !== undefined) {
    const { report: inputReport } = await validate(input, dirname(input), readFileSync(input));
    for (const m of inputReport.issues.messages)
      if (m.severity === 1) inputWarnings.add(`${m.code} ${m.pointer}`);
  }
  const fromInput = (m) => m.severity === 1 && inputWarnings.has(`${m.code} ${m.pointer}`);
  const ownWarnings = issues.messages.filter((m) => m.severity === 1 && !fromInput(m)).length;
  const ok = issues.numErrors === 0 && ownWarnings === 0 && outside.length === 0;
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${file}: ${issues.numErrors} errors, ${issues.numWarnings} warnings` +
              `${input !== undefined ? ` (${issues.numWarnings - ownWarnings} of them the input's too: ${input})` : ''}, ` +
              `${issues.numInfos} infos, ${issues.numHints} hints (glTF-Validator ${report.validatorVersion})`);
  for (const [key, list] of [...byCode].sort()) {
    console.log(`     ${key} x ${list.length} (${describePointers(list)}): ${list[0].message}`);
    if (key.startsWith('error') || key.startsWith('warning'))
      for (const m of list) console.log(`       ${m.pointer || ''}: ${m.message}${fromInput(m) ? ' (the input has it too)' : ''}`);
    infoTotals.set(key, (infoTotals.get(key) || 0) + list.length);
  }
  if (outside.length) console.log(`     URIs outside the folder: ${outside.join(', ')}`);
  if (!ok) failures++;

  // The extension against the manifest.
  let json;
  try {
    json = file.endsWith('.glb') ? readGlbJson(bytes) : JSON.parse(bytes.toString('utf8'));
  } catch (e) {
    console.log(`FAIL ${file}: cannot read its JSON: ${e.message}`);
    failures++;
    continue;
  }
  const manifest = readJson(join(dir, 'manifest.json'));
  const own = checkLightmaps(file, json, manifest, basename(dir).endsWith(ATLAS_UV_SUFFIX));
  const lightmapped = (json.nodes || []).filter((n) => n.extensions && n.extensions.MX_lightmap).length;
  const uv1 = (json.meshes || []).reduce((a, m) => a + m.primitives.filter((p) => p.attributes.TEXCOORD_1 !== undefined).length, 0);
  if (own.length) {
    failures++;
    for (const f of own) console.log(`FAIL ${f}`);
  } else {
    console.log(`ok   ${file}: MX_lightmap on ${lightmapped} nodes agrees with manifest.json; ` +
                `${uv1} primitives with TEXCOORD_1, each used by a lightmap`);
  }
}
console.log('all outputs, by severity and code: ' +
            ([...infoTotals].map(([k, v]) => `${k} x ${v}`).join(', ') || 'no issues'));
console.log(`${outputs.length} outputs validated in ${((performance.now() - t0) / 1000).toFixed(1)} s`);
if (failures) {
  console.error(`FAILED: ${failures} check(s) of ${outputs.length} outputs failed`);
  process.exit(1);
}
console.log('PASSED');
