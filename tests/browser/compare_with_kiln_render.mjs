#!/usr/bin/env node
// compare_with_kiln_render.mjs: renders each bake of bake_scenes.mjs twice from the same
// camera, with `kiln render` (the preview: albedo x lightmap from the EXR pages) and with
// three.js + tools/web/kiln-lightmap.js in headless Chromium (SwiftShader WebGL 2, the
// shipped viewer.html with static=1: the PNG / RGBM pages through the MX_lightmap
// extension), and checks that the two images agree:
//   - display values (sRGB-encoded 8-bit, after kiln render's exposure and ACES curve, which
//     tools/web/kiln-display.js applies in the browser): the mean absolute difference over
//     pixels and channels is at most 2% of kiln render's mean;
//   - linear radiance (kiln render --linear EXR against the browser's float render target):
//     the same bound.
// Where the output has probe-lit nodes (objects too small for a lightmap, lit by their
// extras.kiln.probeSH), the viewer must light every one of their meshes, and where the camera
// sees them (the viewer's probeLitMask, shrunk by a pixel so that silhouettes, where the two
// rasterizations differ, are left out) their mean linear radiance in three.js must be within
// PROBE_TOLERANCE of kiln render's: the whole-image bounds alone would let a small object
// drawn black pass.
// It prints both comparisons per scene and writes OUT/<scene>/{kiln,three,compare}.png
// (compare = kiln render | three.js | |difference| x 4, display values). With --shared DIR
// it compares the bakes of the shared folder's real scenes (bake_scenes.mjs --shared), and
// skips (exit 77) when they are not there.
//
//   node tests/browser/compare_with_kiln_render.mjs --kiln KILN --bakes DIR --out DIR [--shared DIR]
// Exit: 0 pass, 1 fail, 77 skipped (no Chromium, or tools/web's npm packages missing; not
// under CI=true, where that fails).
import { spawnSync } from 'node:child_process';
import { cpSync, existsSync, mkdirSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { join, relative } from 'node:path';
import {
  ATLAS_UV_SUFFIX, compareImages, fileExists, importThree, requireWebPackage, outputOf, parseArgs, readJson, readPng,
  rgbImage, selectScenes, sideBySide, skipOrFail, webDir, writePng, bakeDir,
} from './common.mjs';

const TOLERANCE = 0.02;  // relative mean difference, both in display and linear values
// Relative difference of the probe-lit pixels' mean linear radiance (three.js against kiln
// render). Both evaluate the same SH for the same normals; what remains is rasterization
// against ray casting at pixel centres and the half-float / 8-bit base colour textures.
const PROBE_TOLERANCE = 0.03;
// Fewer probe-lit pixels than this (after shrinking) are too few to compare: they are then
// mostly the edges of thin, distant objects (the breakfast room's chair legs from its main
// camera: 144 pixels, 2.1% apart), where three.js's mipmapped base colour textures and kiln
// render's full-resolution bilinear lookups differ, not the probe light.
const PROBE_MIN_PIXELS = 500;

const args = parseArgs(process.argv.slice(2), ['kiln', 'bakes', 'out'],
                       'compare_with_kiln_render.mjs --kiln KILN --bakes DIR --out DIR [--shared DIR] [--chromium PATH]');
const { list: scenes, shared } = selectScenes(args);

function findChromium() {
  const candidates = [args.chromium, process.env.KILN_CHROMIUM, '/usr/bin/chromium',
                      '/usr/bin/chromium-browser'].filter(Boolean);
  return candidates.find((p) => existsSync(p)) || null;
}

const chromium = findChromium();
if (!chromium)
  skipOrFail('Chromium not found (/usr/bin/chromium; install Debian\'s chromium with ' +
             'tools/install_deps.sh, or give --chromium PATH / KILN_CHROMIUM)');
const puppeteer = requireWebPackage('puppeteer-core');
const { PNG } = requireWebPackage('pngjs');
const three = await importThree();
const { EXRLoader } = await importThree('examples/jsm/loaders/EXRLoader.js');
const { createStaticServer, listenLocal } = await import(join(webDir, 'serve.js'));

// kiln render's EXR (linear radiance) as an RGB image with row 0 at the top.
function readExr(path) {
  const buffer = readFileSync(path);
  const loader = new EXRLoader();
  loader.setDataType(three.FloatType);
  const exr = loader.parse(buffer.buffer.slice(buffer.byteOffset, buffer.byteOffset + buffer.byteLength));
  const channels = exr.data.length / (exr.width * exr.height);
  const img = rgbImage(exr.width, exr.height);
  // EXRLoader writes rows bottom-up (WebGL's order).
  for (let y = 0; y < exr.height; ++y)
    for (let x = 0; x < exr.width; ++x)
      for (let c = 0; c < 3; ++c)
        img.data[3 * (y * exr.width + x) + c] =
            exr.data[channels * ((exr.height - 1 - y) * exr.width + x) + c];
  return img;
}

function fromRgba(width, height, rgba, scale = 1) {
  const img = rgbImage(width, height);
  for (let i = 0; i < width * height; ++i)
    for (let c = 0; c < 3; ++c) img.data[3 * i + c] = rgba[4 * i + c] * scale;
  return img;
}

// What the viewer must find in an output: lightmapped nodes (MX_lightmap) and baked lights.
function expectedCounts(gltfPath) {
  let json;
  if (gltfPath.endsWith('.glb')) {
    const b = readFileSync(gltfPath);
    const length = b.readUInt32LE(12);
    json = JSON.parse(b.subarray(20, 20 + length).toString('utf8'));
  } else {
    json = readJson(gltfPath);
  }
  // Meshes of lightmapped nodes: one three.js mesh per primitive of each node that the scene
  // holds (nodes are counted once per use in the scene's hierarchy).
  const scene = json.scenes[json.scene || 0];
  let meshes = 0, probeLit = 0, lights = 0;
  const visit = (n) => {
    const node = json.nodes[n];
    if (node.mesh !== undefined && node.extensions && node.extensions.MX_lightmap)
      meshes += json.meshes[node.mesh].primitives.length;
    else if (node.mesh !== undefined && node.extras && node.extras.kiln && node.extras.kiln.probeSH)
      probeLit += json.meshes[node.mesh].primitives.length;
    const light = node.extensions && node.extensions.KHR_lights_punctual;
    if (light) {
      const def = json.extensions.KHR_lights_punctual.lights[light.light];
      if (def.extras && def.extras.kiln && def.extras.kiln.baked === true) ++lights;
    }
    for (const c of node.children || []) visit(c);
  };
  for (const n of scene.nodes || []) visit(n);
  return { meshes, probeLit, lights };
}

// The probe-lit pixels of a probeLitMask read-back (RGBA floats, row 0 at the top) whose 3 x 3
// neighbourhood is probe-lit too.
function probeLitPixels(mask, w, h) {
  const inside = (x, y) => x >= 0 && y >= 0 && x < w && y < h && mask[4 * (y * w + x)] > 0.5;
  const pixels = [];
  for (let y = 0; y < h; ++y)
    for (let x = 0; x < w; ++x) {
      let all = true;
      for (let dy = -1; dy <= 1 && all; ++dy)
        for (let dx = -1; dx <= 1 && all; ++dx) all = inside(x + dx, y + dy);
      if (all) pixels.push(y * w + x);
    }
  return pixels;
}

// Mean linear radiance (over RGB) of two images over `pixels`.
function maskedMeans(a, b, pixels) {
  let sumA = 0, sumB = 0;
  for (const i of pixels)
    for (let c = 0; c < 3; ++c) {
      sumA += a.data[3 * i + c];
      sumB += b.data[3 * i + c];
    }
  const n = 3 * Math.max(pixels.length, 1);
  return { three: sumA / n, kiln: sumB / n };
}

const t0 = performance.now();
const jobs = [];
for (const s of scenes) {
  jobs.push({ ...s, label: s.name, dir: bakeDir(args.bakes, s), file: outputOf(args.bakes, s) });
  // More cameras on the same bake (common.mjs: views).
  for (const v of s.views || [])
    jobs.push({ ...s, ...v, label: `${s.name} (${v.name})`, name: `${s.name}_${v.name}`,
                dir: bakeDir(args.bakes, s), file: outputOf(args.bakes, s) });
  const glbDir = join(args.bakes, `${s.name}_glb`);
  const glb = join(glbDir, s.scene.replace(/\.gltf$/, '.glb'));
  if (shared) continue;  // the .glb, --atlas-uv and bad-input checks are the shipped scenes'
  if (s === scenes[0]) jobs.push({ ...s, label: `${s.name} (.glb)`, name: `${s.name}_glb`, dir: glbDir, file: glb });
  // --atlas-uv: both read the output glTF, whose TEXCOORD_1 holds the atlas UV (identity
  // transforms in MX_lightmap; kiln render sees settings.atlasUv in the manifest).
  const atlasDir = join(args.bakes, `${s.name}${ATLAS_UV_SUFFIX}`);
  if (s === scenes[0])
    jobs.push({ ...s, label: `${s.name} (--atlas-uv)`, name: `${s.name}${ATLAS_UV_SUFFIX}`, dir: atlasDir,
                file: join(atlasDir, s.scene) });
}
for (const job of jobs)
  if (!fileExists(job.file)) {
    console.error(`FAILED: ${job.file} is missing: run tests/browser/bake_scenes.mjs first ` +
                  '(the CTest fixture browser_bakes does)');
    process.exit(1);
  }

mkdirSync(args.out, { recursive: true });
const server = createStaticServer({
  '/': webDir,
  '/three/': join(webDir, 'node_modules', 'three'),
  '/data/': args.bakes,
  '/out/': args.out,
});
const port = await listenLocal(server);
const browser = await puppeteer.launch({
  executablePath: chromium,
  headless: true,
  // SwiftShader WebGL; --no-sandbox because tests run as root in CI; no background
  // connections (the machine's network is closed: they would only fail and slow start-up).
  args: ['--headless=new', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
         '--ignore-gpu-blocklist', '--no-sandbox', '--disable-dev-shm-usage',
         '--disable-background-networking', '--disable-component-update', '--disable-sync',
         '--disable-quic', '--no-first-run'],
});

let failures = 0;
const rows = [];
try {
  for (const job of jobs) {
    const out = join(args.out, job.name);
    mkdirSync(out, { recursive: true });
    const [w, h] = job.size;
    const kilnPng = join(out, 'kiln.png'), kilnExr = join(out, 'kiln.exr');
    // kiln render of the output glTF with its lightmaps folder.
    const renderArgs = ['render', job.file, '--lightmaps', job.dir,
                        '--look-from', job.from.join(','), '--look-at', job.at.join(','),
                        '--fov', String(job.fov), '--size', `${w},${h}`,
                        '--exposure', String(job.exposure), '--quiet',
                        '--out', kilnPng, '--linear', kilnExr];
    const tr = performance.now();
    const r = spawnSync(args.kiln, renderArgs, { encoding: 'utf8' });
    if (r.error || r.status !== 0) {
      console.error(`FAILED: kiln ${renderArgs.join(' ')}: ${r.error ? r.error.message : 'exit ' + r.status}\n${r.stdout}${r.stderr}`);
      failures++;
      continue;
    }
    const kilnSeconds = (performance.now() - tr) / 1000;

    // three.js in Chromium.
    const page = await browser.newPage();
    const messages = [];
    page.on('console', (m) => messages.push(`${m.type()}: ${m.text()}`));
    page.on('pageerror', (e) => messages.push(`pageerror: ${e.message}`));
    const query = new URLSearchParams({
      gltf: '/data/' + relative(args.bakes, job.file).split('\\').join('/'),
      from: job.from.join(','), at: job.at.join(','), fov: String(job.fov),
      size: `${w},${h}`, exposure: String(job.exposure), static: '1',
    });
    const tb = performance.now();
    await page.goto(`http://127.0.0.1:${port}/viewer.html?${query}`);
    let result;
    try {
      result = await page.evaluate(async () => {
        const v = await window.kilnViewer;
        const linear = v.readLinear();
        const gl = v.renderer.getContext();
        const { width, height } = v.renderer.domElement;
        const bytes = new Uint8Array(width * height * 4);
        gl.bindFramebuffer(gl.FRAMEBUFFER, null);
        gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, bytes);
        const toBase64 = (u8) => {
          let s = '';
          for (let i = 0; i < u8.length; i += 0x8000)
            s += String.fromCharCode.apply(null, u8.subarray(i, i + 0x8000));
          return btoa(s);
        };
        const mask = v.info.probeLitMeshes > 0 ? toBase64(new Uint8Array(v.probeLitMask().buffer)) : null;
        return { info: v.info, width, height, linear: toBase64(new Uint8Array(linear.buffer)),
                 display: toBase64(bytes), mask };
      });
    } catch (e) {
      console.error(`FAILED: ${job.label}: the viewer failed: ${e.message}\n${messages.join('\n')}`);
      failures++;
      await page.close();
      continue;
    }
    const browserSeconds = (performance.now() - tb) / 1000;
    await page.close();

    const warnings = messages.filter((m) => !m.startsWith('log:') && !m.startsWith('debug:') &&
                                            !m.startsWith('info:'));
    if (warnings.length) {
      console.error(`FAILED: ${job.label}: the page reported:\n  ${warnings.join('\n  ')}`);
      failures++;
    }
    const expected = expectedCounts(job.file);
    if (result.info.lightmappedMeshes !== expected.meshes || result.info.hiddenBakedLights !== expected.lights ||
        result.info.probeLitMeshes !== expected.probeLit) {
      console.error(`FAILED: ${job.label}: the viewer lightmapped ${result.info.lightmappedMeshes} meshes, ` +
                    `lit ${result.info.probeLitMeshes} by their probe light ` +
                    `and hid ${result.info.hiddenBakedLights} baked lights; the file has ` +
                    `${expected.meshes} lightmapped meshes, ${expected.probeLit} probe-lit meshes ` +
                    `and ${expected.lights} baked lights`);
      failures++;
    }
    if (result.width !== w || result.height !== h) {
      console.error(`FAILED: ${job.label}: the canvas is ${result.width} x ${result.height}, not ${w} x ${h}`);
      failures++;
      continue;
    }
    const linearBytes = Buffer.from(result.linear, 'base64');
    const threeLinear = fromRgba(w, h, new Float32Array(linearBytes.buffer, linearBytes.byteOffset, w * h * 4));
    // readPixels of the canvas: bottom-up rows.
    const displayBytes = Buffer.from(result.display, 'base64');
    const flipped = new Uint8Array(w * h * 4);
    for (let y = 0; y < h; ++y)
      flipped.set(displayBytes.subarray((h - 1 - y) * w * 4, (h - y) * w * 4), y * w * 4);
    const threeDisplay = fromRgba(w, h, flipped, 1 / 255);

    const kilnDisplay = readPng(PNG, kilnPng);
    const kilnLinear = readExr(kilnExr);
    const display = compareImages(threeDisplay, kilnDisplay);
    const linear = compareImages(threeLinear, kilnLinear);
    writePng(PNG, join(out, 'three.png'), threeDisplay);
    writePng(PNG, join(out, 'compare.png'), sideBySide(kilnDisplay, threeDisplay, display.diff));

    let probe = null;
    if (result.mask) {
      const maskBytes = Buffer.from(result.mask, 'base64');
      const pixels = probeLitPixels(new Float32Array(maskBytes.buffer, maskBytes.byteOffset, w * h * 4), w, h);
      if (pixels.length >= PROBE_MIN_PIXELS) {
        const m = maskedMeans(threeLinear, kilnLinear, pixels);
        const relative = m.kiln > 0 ? Math.abs(m.three - m.kiln) / m.kiln : Infinity;
        probe = { pixels: pixels.length, ...m, relative, ok: relative <= PROBE_TOLERANCE };
      } else {
        // A view made to show probe-lit objects (common.mjs: probeLitInView) must show them.
        probe = { pixels: pixels.length, ok: job.probeLitInView ? false : undefined };
      }
    } else if (job.probeLitInView) {
      probe = { pixels: 0, ok: false };
    }
    const ok = display.relative <= TOLERANCE && linear.relative <= TOLERANCE &&
               (!probe || probe.ok !== false);
    if (!ok) failures++;
    rows.push({ job, display, linear, kilnSeconds, browserSeconds, ok });
    console.log(`${ok ? 'ok  ' : 'FAIL'} ${job.label} (${w} x ${h}, exposure ${job.exposure}): ` +
                `kiln render ${kilnSeconds.toFixed(2)} s, browser ${browserSeconds.toFixed(2)} s; ` +
                `${result.info.lightmappedMeshes} lightmapped meshes, ${result.info.hiddenBakedLights} baked lights hidden`);
    console.log(`     display (sRGB 0-1): mean three.js ${display.meanA.toFixed(5)}, kiln render ` +
                `${display.meanB.toFixed(5)}, mean |diff| ${display.meanAbs.toFixed(5)} = ` +
                `${(100 * display.relative).toFixed(3)}% of kiln render's mean (limit ${100 * TOLERANCE}%)`);
    console.log(`     linear radiance:    mean three.js ${linear.meanA.toFixed(5)}, kiln render ` +
                `${linear.meanB.toFixed(5)}, mean |diff| ${linear.meanAbs.toFixed(5)} = ` +
                `${(100 * linear.relative).toFixed(3)}% of kiln render's mean (limit ${100 * TOLERANCE}%)`);
    if (probe && probe.relative !== undefined)
      console.log(`     probe-lit objects:  ${probe.pixels} pixels, mean three.js ${probe.three.toFixed(5)}, ` +
                  `kiln render ${probe.kiln.toFixed(5)}, difference ${(100 * probe.relative).toFixed(3)}% ` +
                  `(limit ${100 * PROBE_TOLERANCE}%)`);
    else if (probe)
      console.log(`     probe-lit objects:  ${probe.pixels} pixels in view, too few to compare` +
                  (probe.ok === false ? ' (FAIL: this view is made to show them)' : ''));
    console.log(`     images: ${join(out, 'compare.png')} (kiln render | three.js | |diff| x 4)`);
  }

  // Bad input: a copy of the Cornell box output whose node 0 has an unknown encoding and
  // node 1 a texture index out of range must load, with one warning per broken node that
  // names the node and the field, and those two nodes without a lightmap.
  if (!shared) {
    const badDir = join(args.out, 'bad_input');
    rmSync(badDir, { recursive: true, force: true });
    cpSync(bakeDir(args.bakes, scenes[0]), badDir, { recursive: true });
    const badFile = join(badDir, scenes[0].scene);
    const bad = readJson(badFile);
    const lightmappedNodes = bad.nodes.map((n, i) => (n.extensions && n.extensions.MX_lightmap ? i : -1)).filter((i) => i >= 0);
    if (lightmappedNodes.length < 2) {
      console.error(`FAILED: bad input: ${badFile} has fewer than 2 nodes with MX_lightmap`);
      failures++;
    } else {
      const [a, b] = lightmappedNodes;
      const extA = bad.nodes[a].extensions.MX_lightmap;
      extA.extras = { ...(extA.extras || {}), kiln: { ...((extA.extras || {}).kiln || {}), encoding: 'hdr' } };
      bad.nodes[b].extensions.MX_lightmap.lightMapTexture.index = 99;
      writeFileSync(badFile, JSON.stringify(bad));
      const page = await browser.newPage();
      const messages = [];
      page.on('console', (m) => messages.push(`${m.type()}: ${m.text()}`));
      page.on('pageerror', (e) => messages.push(`pageerror: ${e.message}`));
      await page.goto(`http://127.0.0.1:${port}/viewer.html?static=1&size=64,64&gltf=/out/bad_input/${scenes[0].scene}`);
      const info = await page.evaluate(() => window.kilnViewer.then((v) => v.info, (e) => 'rejected: ' + e.message));
      await page.close();
      const expected = expectedCounts(badFile);  // counts nodes that still have the extension
      const primitives = (n) => bad.meshes[bad.nodes[n].mesh].primitives.length;
      const wantMeshes = expected.meshes - primitives(a) - primitives(b);
      const warnings = messages.filter((m) => m.startsWith('warn'));
      const nameA = `nodes[${a}] ("${bad.nodes[a].name}").extensions.MX_lightmap.extras.kiln.encoding: "hdr" is not dldr or rgbm`;
      const nameB = `nodes[${b}] ("${bad.nodes[b].name}").extensions.MX_lightmap.lightMapTexture.index: expected a texture index below`;
      const ok = typeof info === 'object' && info.lightmappedMeshes === wantMeshes && warnings.length === 2 &&
                 warnings.some((w) => w.includes(nameA)) && warnings.some((w) => w.includes(nameB)) &&
                 messages.length === warnings.length;
      if (!ok) failures++;
      console.log(`${ok ? 'ok  ' : 'FAIL'} bad input (node ${a} unknown encoding, node ${b} texture 99): ` +
                  `${typeof info === 'object' ? info.lightmappedMeshes : info} lightmapped meshes ` +
                  `(expected ${wantMeshes}); page messages:\n       ${messages.join('\n       ')}`);
    }
  }
} finally {
  await browser.close();
  server.close();
}
console.log(`${jobs.length} renders compared in ${((performance.now() - t0) / 1000).toFixed(1)} s`);
if (failures) {
  console.error(`FAILED: ${failures} problem(s)`);
  process.exit(1);
}
console.log('PASSED');
