#!/usr/bin/env node
// serve.js: a tiny static file server for kiln's three.js viewer (viewer.html) and the browser
// test. Listens on 127.0.0.1 only (never on other interfaces): it serves files from disk.
//
//   node tools/web/serve.js [--port 8080] [--data DIR]
//   then open http://127.0.0.1:8080/viewer.html?gltf=/data/cornell_box.gltf
//
// Mounts: "/" = this folder (viewer.html, kiln-lightmap.js, kiln-display.js), "/three/" =
// node_modules/three (so the pages' import map finds three.js), "/data/" = DIR (a `kiln bake`
// output folder; default: the current directory). Only GET and HEAD; paths that leave their
// mount (.., symlinks out) are refused.
import { createServer } from 'node:http';
import { createReadStream, realpathSync, statSync } from 'node:fs';
import { extname, join, resolve, sep, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));

const types = {
  '.html': 'text/html; charset=utf-8',
  '.js': 'text/javascript; charset=utf-8',
  '.mjs': 'text/javascript; charset=utf-8',
  '.json': 'application/json',
  '.gltf': 'model/gltf+json',
  '.glb': 'model/gltf-binary',
  '.bin': 'application/octet-stream',
  '.png': 'image/png',
  '.jpg': 'image/jpeg',
  '.jpeg': 'image/jpeg',
  '.ktx2': 'image/ktx2',
  '.exr': 'image/x-exr',
  '.wasm': 'application/wasm',
  '.css': 'text/css',
};

// mounts: {"/prefix/": "/abs/dir"}; longest prefix wins.
export function createStaticServer(mounts) {
  const entries = Object.entries(mounts)
    .map(([prefix, dir]) => [prefix, realpathSync(resolve(dir))])
    .sort((a, b) => b[0].length - a[0].length);
  return createServer((req, res) => {
    const fail = (code, text) => {
      res.writeHead(code, { 'content-type': 'text/plain' });
      res.end(text + '\n');
    };
    if (req.method !== 'GET' && req.method !== 'HEAD') return fail(405, 'method not allowed');
    let path;
    try {
      path = decodeURIComponent(new URL(req.url, 'http://127.0.0.1').pathname);
    } catch {
      return fail(400, 'bad url');
    }
    const mount = entries.find(([prefix]) => path.startsWith(prefix));
    if (!mount) return fail(404, 'not found: ' + path);
    const [prefix, root] = mount;
    let file;
    try {
      file = realpathSync(join(root, path.slice(prefix.length)));
    } catch {
      return fail(404, 'not found: ' + path);
    }
    if (file !== root && !file.startsWith(root + sep)) return fail(403, 'outside the served folder');
    let stat;
    try {
      stat = statSync(file);
    } catch {
      return fail(404, 'not found: ' + path);
    }
    if (stat.isDirectory()) return fail(404, 'a folder: ' + path);
    res.writeHead(200, {
      'content-type': types[extname(file).toLowerCase()] || 'application/octet-stream',
      'content-length': stat.size,
      'cache-control': 'no-store',
    });
    if (req.method === 'HEAD') return res.end();
    createReadStream(file).pipe(res);
  });
}

// The default mounts of the viewer: this folder, three.js, and a data folder.
export function viewerMounts(dataDir) {
  return {
    '/': here,
    '/three/': join(here, 'node_modules', 'three'),
    '/data/': dataDir,
  };
}

// Starts `server` on 127.0.0.1 (port 0: any free port); resolves to the port.
export function listenLocal(server, port = 0) {
  return new Promise((resolvePort, reject) => {
    server.once('error', reject);
    server.listen(port, '127.0.0.1', () => resolvePort(server.address().port));
  });
}

if (process.argv[1] && resolve(process.argv[1]) === fileURLToPath(import.meta.url)) {
  const args = process.argv.slice(2);
  let port = 8080;
  let data = process.cwd();
  for (let i = 0; i < args.length; ++i) {
    if (args[i] === '--port' && i + 1 < args.length) port = Number(args[++i]);
    else if (args[i] === '--data' && i + 1 < args.length) data = args[++i];
    else {
      console.error('usage: node serve.js [--port 8080] [--data DIR]');
      process.exit(2);
    }
  }
  if (!Number.isInteger(port) || port < 0 || port > 65535) {
    console.error(`serve.js: --port: expected an integer in 0..65535`);
    process.exit(2);
  }
  try {
    if (!statSync(data).isDirectory()) throw new Error('not a folder');
  } catch {
    console.error(`serve.js: --data ${data}: no such folder`);
    process.exit(1);
  }
  const server = createStaticServer(viewerMounts(data));
  listenLocal(server, port).then(
    (p) => console.log(`serving ${here} and /data/ = ${resolve(data)} at http://127.0.0.1:${p}/` +
                       `viewer.html?gltf=/data/<file>.gltf (Ctrl-C to stop)`),
    (e) => {
      console.error(`serve.js: cannot listen on 127.0.0.1:${port}: ${e.message}`);
      process.exit(1);
    });
}
