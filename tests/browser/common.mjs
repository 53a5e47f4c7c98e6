// common.mjs: what the browser and validator tests share: the scenes they bake, argument
// parsing, skipping, images.
import { existsSync, readFileSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

export const repoRoot = resolve(dirname(fileURLToPath(import.meta.url)), '..', '..');
export const webDir = join(repoRoot, 'tools', 'web');
export const scenesDir = join(repoRoot, 'tools', 'scenes');

// The folder suffix of the --atlas-uv bake (bake_scenes.mjs): its extension's scale and
// offset are identity, the atlas transform being in TEXCOORD_1.
export const ATLAS_UV_SUFFIX = '_atlas_uv';

// CTest's SKIP_RETURN_CODE for these tests.
export const SKIP = 77;

// The bakes (tests/browser/bake_scenes.mjs) and the view each scene is compared from. The
// cameras are the scenes' own glTF cameras written as look-from / look-at / vertical fov
// (tools/scenes/*.gltf, camera nodes: position, position + rotation x (0, 0, -1), yfov),
// so that both renderers get them in the one form both take.
export const scenes = [
  {
    name: 'cornell_box', scene: 'cornell_box.gltf', ldr: 'dldr',
    bake: ['--preset', 'low', '--resolution', '60'],
    from: [0.278, 0.273, -0.8], at: [0.278, 0.273, 0.2], fov: 39.3076481, size: [256, 256],
    exposure: 0,
  },
  {
    name: 'two_rooms', scene: 'two_rooms.gltf', ldr: 'rgbm',
    bake: ['--preset', 'low'],
    from: [0.4, 1.7, 3.6], at: [1.2257, 1.4477, 3.0954], fov: 70, size: [320, 180],
    exposure: 1,
  },
  {
    // The Cornell box with the short block's five faces and the tall block's top too small
    // for a lightmap (--min-object-texels 150 at 60 texels per unit): three.js lights them
    // from the probe light the bake wrote on their nodes (extras.kiln.probeSH), which
    // compare_with_kiln_render.mjs compares with kiln render on their pixels alone.
    name: 'cornell_box_probe_lit', scene: 'cornell_box.gltf', ldr: 'dldr',
    bake: ['--preset', 'low', '--resolution', '60', '--min-object-texels', '150'],
    from: [0.278, 0.273, -0.8], at: [0.278, 0.273, 0.2], fov: 39.3076481, size: [256, 256],
    exposure: 0, probeLitInView: true,
  },
  {
    name: 'courtyard', scene: 'courtyard.gltf', ldr: 'dldr',
    bake: ['--preset', 'low'],
    from: [5.0, 11.0, -13.0], at: [4.669, 10.4207, -12.2552], fov: 60, size: [320, 180],
    exposure: 0,
  },
];

// Real scenes outside the repository, in the project's shared folder (KILN_SHARED_DIR in
// tests/CMakeLists.txt, ../shared beside the repository): `path` is the input glTF, `scene`
// the output's file name (kiln bake names it after the input). They are baked and compared
// with `--shared DIR` (bake_scenes.mjs, compare_with_kiln_render.mjs), the slow browser
// test. The breakfast room (262k triangles, base colour textures, metals, a sun and a sky):
// baked twice, with the default dLDR pages (its sunlit floor and table exceed dLDR's range
// 2 on a few percent of the texels, which three.js then shows clamped) and with RGBM. The
// views are the file's cameras CameraMain and, on the dLDR bake, CameraTableTop (the tea
// set: chrome, metal and ceramic, the marble table top, the tiled floor) as look-from /
// look-at / yfov, as for the shipped scenes. `views` are more cameras on the same bake. With
// the default --min-object-texels auto the tea cups, spoons, lamps and chair legs are lit by
// their probe light at 16 texels per unit; the table-top view shows the cups (probeLitInView:
// compare_with_kiln_render.mjs must compare their pixels).
export function sharedScenes(sharedDir) {
  const breakfast = {
    path: join(sharedDir, 'scenes', 'breakfast_room', 'BreakfastRoom.gltf'),
    scene: 'BreakfastRoom.gltf',
    bake: ['--preset', 'preview', '--resolution', '16'],
    from: [1.1668, 0.9702, 0.6777], at: [0.7596, 0.9859, -0.2355], fov: 45, size: [320, 180],
    exposure: 0,
  };
  return [
    { ...breakfast, name: 'breakfast_room', ldr: 'dldr',
      views: [{ name: 'table_top', from: [-0.9927, 0.8911, -1.2292], at: [-0.1105, 0.7814, -1.6871],
                probeLitInView: true }] },
    { ...breakfast, name: 'breakfast_room_rgbm', ldr: 'rgbm' },
  ];
}

// The input glTF of a scene entry.
export function scenePath(scene) {
  return scene.path || join(scenesDir, scene.scene);
}

// The scenes a script works on: the shipped ones, or with --shared DIR the real scenes of
// the shared folder. A missing shared folder skips (exit 77) with a message, under CI too:
// the shared folder is the project's, not something CI installs.
export function selectScenes(args) {
  if (args.shared === undefined) return { list: scenes, shared: false };
  const list = sharedScenes(resolve(args.shared));
  const missing = list.filter((s) => !existsSync(s.path)).map((s) => s.path);
  if (missing.length) {
    console.log(`SKIPPED: ${[...new Set(missing)].join(', ')} not found (the project's shared ` +
                'folder, KILN_SHARED_DIR: ../shared beside the repository)');
    process.exit(SKIP);
  }
  return { list, shared: true };
}

// --name value pairs into an object; `required` names must be present.
export function parseArgs(argv, required, usage) {
  const out = {};
  for (let i = 0; i < argv.length; ++i) {
    if (!argv[i].startsWith('--') || i + 1 >= argv.length) {
      console.error(`bad argument ${argv[i]}\nusage: ${usage}`);
      process.exit(2);
    }
    out[argv[i].slice(2)] = argv[++i];
  }
  for (const name of required)
    if (out[name] === undefined) {
      console.error(`missing --${name}\nusage: ${usage}`);
      process.exit(2);
    }
  return out;
}

// A missing prerequisite skips the test with a message, except under CI (CI=true), which
// runs tools/install_deps.sh first and must not pass by skipping.
export function skipOrFail(message) {
  if (process.env.CI && process.env.CI !== 'false' && process.env.CI !== '0') {
    console.error(`FAILED: ${message} (CI=${process.env.CI}: CI installs every prerequisite ` +
                  'with tools/install_deps.sh, so a missing one is an error there)');
    process.exit(1);
  }
  console.log(`SKIPPED: ${message}`);
  process.exit(SKIP);
}

// The npm packages of tools/web (installed by `npm ci` in tools/install_deps.sh). CommonJS
// packages (puppeteer-core, pngjs, gltf-validator) through require; three.js's ES modules by
// their file in node_modules/three, so that they and three.js's addons (which import
// 'three' from there) share one three.js.
const webRequire = createRequire(join(webDir, 'package.json'));

export function requireWebPackage(name) {
  try {
    webRequire.resolve(name);
  } catch {
    skipOrFail(`npm package ${name} is not installed in ${webDir} ` +
               '(run tools/install_deps.sh, or `npm ci` in tools/web)');
  }
  return webRequire(name);
}

export async function importThree(file = 'build/three.module.js') {
  try {
    webRequire.resolve('three');
  } catch {
    skipOrFail(`npm package three is not installed in ${webDir} ` +
               '(run tools/install_deps.sh, or `npm ci` in tools/web)');
  }
  return import(pathToFileURL(join(webDir, 'node_modules', 'three', file)).href);
}

export function bakeDir(bakes, scene) {
  return join(bakes, scene.name);
}

// The output glTF (or .glb) of a bake folder: the scene's name with .gltf.
export function outputOf(bakes, scene) {
  return join(bakeDir(bakes, scene), scene.scene);
}

export function readJson(path) {
  return JSON.parse(readFileSync(path, 'utf8'));
}

export function fileExists(path) {
  return existsSync(path);
}

// --- Images: {width, height, data: Float32Array RGB, row 0 at the top} ---

export function rgbImage(width, height) {
  return { width, height, data: new Float32Array(width * height * 3) };
}

// PNG (8-bit) to values / 255, no transfer function undone (as kiln render --compare reads).
export function readPng(PNG, path) {
  const png = PNG.sync.read(readFileSync(path));
  const img = rgbImage(png.width, png.height);
  for (let i = 0; i < png.width * png.height; ++i)
    for (let c = 0; c < 3; ++c) img.data[3 * i + c] = png.data[4 * i + c] / 255;
  return img;
}

export function writePng(PNG, path, img) {
  const png = new PNG({ width: img.width, height: img.height });
  for (let i = 0; i < img.width * img.height; ++i) {
    for (let c = 0; c < 3; ++c)
      png.data[4 * i + c] = Math.round(Math.min(Math.max(img.data[3 * i + c], 0), 1) * 255);
    png.data[4 * i + 3] = 255;
  }
  writeFileSync(path, PNG.sync.write(png));
}

// Over every pixel and channel of a and b (b the reference, kiln render): mean |a - b|, the
// means, and the relative mean difference sum |a - b| / sum |b| (= mean |a - b| / mean b).
// The same quantities as `kiln render --compare`.
export function compareImages(a, b) {
  if (a.width !== b.width || a.height !== b.height)
    throw new Error(`the images differ in size: ${a.width} x ${a.height} and ${b.width} x ${b.height}`);
  let sumDiff = 0, sumA = 0, sumB = 0;
  const diff = rgbImage(a.width, a.height);
  for (let i = 0; i < a.data.length; ++i) {
    const d = Math.abs(a.data[i] - b.data[i]);
    diff.data[i] = d;
    sumDiff += d;
    sumA += a.data[i];
    sumB += Math.abs(b.data[i]);
  }
  const n = a.data.length;
  return { meanAbs: sumDiff / n, meanA: sumA / n, meanB: sumB / n,
           relative: sumB > 0 ? sumDiff / sumB : 0, diff };
}

// b | a | |a - b| x scale, side by side (display values).
export function sideBySide(b, a, diff, scale = 4) {
  const out = rgbImage(3 * a.width, a.height);
  for (let y = 0; y < a.height; ++y)
    for (let x = 0; x < a.width; ++x)
      for (let c = 0; c < 3; ++c) {
        const i = 3 * (y * a.width + x) + c;
        const row = 3 * y * 3 * a.width;
        out.data[row + 3 * x + c] = b.data[i];
        out.data[row + 3 * (x + a.width) + c] = a.data[i];
        out.data[row + 3 * (x + 2 * a.width) + c] = Math.min(diff.data[i] * scale, 1);
      }
  return out;
}
