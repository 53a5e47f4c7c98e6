#!/usr/bin/env node
// bake_scenes.mjs: the CTest fixture of the browser and validator tests: bakes the scenes of
// common.mjs with `kiln bake` (a low preset: the tests compare renderers of one bake, not a
// bake with the truth) into OUT/<scene>/, and the Cornell box once more with --glb into
// OUT/cornell_box_glb/ and with --atlas-uv into OUT/cornell_box_atlas_uv/. With --shared DIR
// it bakes the real scenes of the shared folder instead (common.mjs, sharedScenes), and
// skips (exit 77) when they are not there.
//
//   node tests/browser/bake_scenes.mjs --kiln build/tools/kiln --out build/tests/browser/bakes [--shared DIR]
import { spawnSync } from 'node:child_process';
import { mkdirSync, rmSync } from 'node:fs';
import { join } from 'node:path';
import { ATLAS_UV_SUFFIX, parseArgs, scenePath, selectScenes } from './common.mjs';

const args = parseArgs(process.argv.slice(2), ['kiln', 'out'],
                       'bake_scenes.mjs --kiln KILN --out DIR [--shared DIR]');
const { list: scenes, shared } = selectScenes(args);

function run(argv) {
  const t0 = performance.now();
  const r = spawnSync(args.kiln, argv, { encoding: 'utf8' });
  const seconds = (performance.now() - t0) / 1000;
  if (r.error) {
    console.error(`FAILED: cannot run ${args.kiln}: ${r.error.message}`);
    process.exit(1);
  }
  if (r.status !== 0) {
    console.error(`FAILED: kiln ${argv.join(' ')} exited ${r.status}\n${r.stdout}${r.stderr}`);
    process.exit(1);
  }
  return { seconds, output: r.stdout + r.stderr };
}

mkdirSync(args.out, { recursive: true });
const jobs = scenes.map((s) => ({ name: s.name, argv: [scenePath(s), ...s.bake, '--ldr', s.ldr] }));
if (!shared) {
  const cornell = scenes[0];
  jobs.push({ name: `${cornell.name}_glb`,
              argv: [scenePath(cornell), ...cornell.bake, '--ldr', cornell.ldr, '--glb'] });
  // The atlas transform in TEXCOORD_1 (identity scale/offset in the extension).
  jobs.push({ name: `${cornell.name}${ATLAS_UV_SUFFIX}`,
              argv: [scenePath(cornell), ...cornell.bake, '--ldr', cornell.ldr, '--atlas-uv'] });
}
for (const job of jobs) {
  const dir = join(args.out, job.name);
  rmSync(dir, { recursive: true, force: true });
  const { seconds, output } = run(['bake', ...job.argv, '--out', dir, '--quiet']);
  console.log(`baked ${job.name}: kiln bake ${job.argv.slice(1).join(' ')} (${seconds.toFixed(1)} s)`);
  // kiln's warnings (dLDR clamping, dropped triangles) belong in the test's log.
  for (const line of output.split('\n')) if (line.includes('warning')) console.log(`  ${line}`);
}
