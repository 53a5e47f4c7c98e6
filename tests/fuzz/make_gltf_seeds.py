#!/usr/bin/env python3
"""make_gltf_seeds.py OUT_DIR: the glTF/.glb seed corpus of fuzz_gltf (tests/fuzz/corpus/gltf).

Small, self-contained scenes (buffers and images as data: URIs or in the GLB BIN chunk) that
between them reach every part of the loader: indexed and non-indexed triangles, strips and
fans, normals, TEXCOORD_0/1, a sampler and an embedded PNG, a sparse accessor, a byteStride,
a node hierarchy with TRS and matrix transforms, punctual lights, a camera, extras.kiln on the
scene and on nodes, and a .glb.
"""
import base64, json, os, struct, sys, zlib

out = sys.argv[1]
os.makedirs(out, exist_ok=True)

def png(w, h, rgba):
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    rows = b"".join(b"\0" + bytes(rgba[y * w * 4:(y + 1) * w * 4]) for y in range(h))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b""))

def quad_scene():
    P = [(0, 0, 0), (1, 0, 0), (1, 0, -1), (0, 0, -1)]
    N = [(0, 1, 0)] * 4
    U = [(0, 0), (1, 0), (1, 1), (0, 1)]
    I = [0, 1, 2, 0, 2, 3]
    buf = bytearray()
    views, accs = [], []
    def add(data, count, typ, comp, mn=None, mx=None, stride=None):
        while len(buf) % 4: buf.append(0)
        views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": len(data)})
        if stride: views[-1]["byteStride"] = stride
        buf.extend(data)
        a = {"bufferView": len(views) - 1, "componentType": comp, "count": count, "type": typ}
        if mn: a["min"], a["max"] = mn, mx
        accs.append(a)
        return len(accs) - 1
    ap = add(b"".join(struct.pack("<3f", *p) for p in P), 4, "VEC3", 5126, [0, 0, -1], [1, 0, 0])
    an = add(b"".join(struct.pack("<3f", *n) for n in N), 4, "VEC3", 5126)
    au = add(b"".join(struct.pack("<2f", *u) for u in U), 4, "VEC2", 5126, stride=8)
    ai = add(struct.pack("<6H", *I), 6, "SCALAR", 5123)
    return buf, views, accs, ap, an, au, ai

def doc(buf, views, accs, meshes, nodes, extra=None):
    g = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": nodes,
         "meshes": meshes, "accessors": accs, "bufferViews": views,
         "buffers": [{"byteLength": len(buf),
                      "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(buf)).decode()}]}
    if extra: g.update(extra)
    return g

def save(name, g):
    with open(os.path.join(out, name), "w") as f:
        json.dump(g, f, separators=(",", ":"))

# 1. the smallest useful scene: one indexed quad with normals and UVs.
buf, views, accs, ap, an, au, ai = quad_scene()
prim = {"attributes": {"POSITION": ap, "NORMAL": an, "TEXCOORD_0": au, "TEXCOORD_1": au}, "indices": ai}
save("quad.gltf", doc(buf, views, accs, [{"primitives": [prim]}], [{"mesh": 0}]))

# 2. a textured material (2x2 PNG, sampler), emissive strength, a hierarchy, lights, a camera,
#    extras.kiln on the scene and a node.
img = png(2, 2, [255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 128])
g = doc(buf, views, accs,
        [{"primitives": [dict(prim, material=0)]}, {"primitives": [dict(prim, mode=6)]}],
        [{"children": [1, 2, 3], "translation": [0, 1, 0], "rotation": [0, 0.7071068, 0, 0.7071068]},
         {"mesh": 0, "scale": [2, 1, 2], "extras": {"kiln": {"static": True, "scaleInLightmap": 2,
                                                             "probes": [[0.5, 0.5, -0.5]]}}},
         {"mesh": 1, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 2, 0, 1],
          "extensions": {"KHR_lights_punctual": {"light": 1}}},
         {"camera": 0, "translation": [0, 1, 3], "extensions": {"KHR_lights_punctual": {"light": 0}}}],
        {"materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "texCoord": 0},
                                                 "baseColorFactor": [1, 1, 1, 1]},
                        "emissiveFactor": [1, 0.5, 0], "doubleSided": True, "alphaMode": "MASK",
                        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 3}}}],
         "textures": [{"source": 0, "sampler": 0}],
         "samplers": [{"magFilter": 9728, "wrapS": 33071, "wrapT": 33648}],
         "images": [{"uri": "data:image/png;base64," + base64.b64encode(img).decode()}],
         "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
         "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
         "extensions": {"KHR_lights_punctual": {"lights": [
             {"type": "directional", "color": [1, 1, 1], "intensity": 3},
             {"type": "spot", "intensity": 20, "range": 10,
              "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}}]}}})
g["scenes"][0]["extras"] = {"kiln": {"sky": {"color": [0.3, 0.4, 0.6]}, "bounces": 2,
                                     "lightmapResolution": 8, "lightmapMaxSize": 64}}
save("textured_lights_hierarchy.gltf", g)

# 3. a sparse accessor (positions moved by two sparse entries) and a non-indexed strip.
buf, views, accs, ap, an, au, ai = quad_scene()
while len(buf) % 4: buf.append(0)
views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": 2 + 2 + 24})
buf.extend(struct.pack("<2H", 1, 3))
views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": 24})
buf.extend(struct.pack("<6f", 1, 0.5, 0, 0, 0.5, -1))
views[-2]["byteLength"] = 4
accs.append({"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "sparse": {"count": 2, "indices": {"bufferView": len(views) - 2, "componentType": 5123},
                        "values": {"bufferView": len(views) - 1}}})
save("sparse_strip.gltf",
     doc(buf, views, accs, [{"primitives": [{"attributes": {"POSITION": len(accs) - 1}, "mode": 5}]}],
         [{"mesh": 0}]))

# 4. the quad as a .glb (JSON chunk + BIN chunk, no buffer uri).
buf, views, accs, ap, an, au, ai = quad_scene()
g = doc(buf, views, accs, [{"primitives": [prim]}], [{"mesh": 0}])
del g["buffers"][0]["uri"]
js = json.dumps(g, separators=(",", ":")).encode()
js += b" " * (-len(js) % 4)
bb = bytes(buf) + b"\0" * (-len(buf) % 4)
body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(bb), b"BIN\0") + bb
with open(os.path.join(out, "quad.glb"), "wb") as f:
    f.write(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
