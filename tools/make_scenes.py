#!/usr/bin/env python3
# make_scenes.py: writes the glTF 2.0 test scenes that kiln ships (cornell_box, two_rooms,
# two_rooms_thin, courtyard, atrium; see docs/scenes.md) and validates them. Python 3 standard
# library only.
#
#   python3 tools/make_scenes.py [--out DIR]          write the scenes (default: tools/scenes),
#                                                     then validate what was written
#   python3 tools/make_scenes.py --check [--out DIR]  only validate the scenes already in DIR
#
# Output is deterministic: the same script gives the same bytes (PNG bytes depend on the
# zlib version's compressor). Geometry is built from planar convex faces with flat normals,
# counter-clockwise seen from the front; every mesh gets TEXCOORD_0 (metres in the face's
# plane, or the texture's [0,1] square for textured faces) and TEXCOORD_1, a lightmap UV set
# whose charts (one per plane) are packed inside [0,1]^2 with a 2% gutter between charts and
# from the border, all charts of an object at one scale (uniform texel density).
import argparse
import json
import math
import os
import struct
import sys
import zlib

GUTTER = 0.02  # lightmap UV gutter, in UV units, between charts and from the border


# ----------------------------------------------------------------------------- vectors
def vadd(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def vsub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def vmul(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


def vdot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def vcross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def vlen(a):
    return math.sqrt(vdot(a, a))


def vnorm(a):
    length = vlen(a)
    assert length > 0.0
    return (a[0] / length, a[1] / length, a[2] / length)


def newell(pts):
    """Area-weighted normal of a polygon (length = 2 x area), counter-clockwise = front."""
    n = [0.0, 0.0, 0.0]
    for i in range(len(pts)):
        a, b = pts[i], pts[(i + 1) % len(pts)]
        n[0] += (a[1] - b[1]) * (a[2] + b[2])
        n[1] += (a[2] - b[2]) * (a[0] + b[0])
        n[2] += (a[0] - b[0]) * (a[1] + b[1])
    return tuple(n)


def f32(x):
    """x rounded to the float32 the .bin stores."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def rnd(x, digits=7):
    """A tidy JSON number (and one that does not depend on libm's last bit)."""
    v = round(x, digits)
    return 0.0 if v == 0.0 else v


def quat_from_basis(x, y, z):
    """Unit quaternion [x, y, z, w] of the rotation whose matrix has columns x, y, z."""
    m = [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        q = ((m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, 0.25 * s)
    elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2]) * 2.0
        q = (0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s)
    elif m[1][1] > m[2][2]:
        s = math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2]) * 2.0
        q = ((m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s)
    else:
        s = math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1]) * 2.0
        q = ((m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s, (m[1][0] - m[0][1]) / s)
    if q[3] < 0.0:
        q = tuple(-c for c in q)
    return [rnd(c) for c in q]


def look_rotation(forward, up=(0.0, 1.0, 0.0)):
    """Rotation taking a node's -Z to `forward` with its +Y towards `up` (cameras, lights)."""
    f = vnorm(forward)
    if abs(vdot(f, vnorm(up))) > 0.999:
        up = (0.0, 0.0, 1.0)
    x = vnorm(vcross(f, up))
    y = vcross(x, f)
    return quat_from_basis(x, y, vmul(f, -1.0))


def quat_y(degrees):
    h = math.radians(degrees) * 0.5
    return [0.0, rnd(math.sin(h)), 0.0, rnd(math.cos(h))]


def rotate_y(p, degrees):
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return (c * p[0] + s * p[2], p[1], -s * p[0] + c * p[2])


def sun_direction(elevation_deg, azimuth_deg):
    """Direction sunlight travels: down at `elevation`, horizontally towards +Z turned by
    `azimuth` towards +X."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return (math.cos(el) * math.sin(az), -math.sin(el), math.cos(el) * math.cos(az))


# ----------------------------------------------------------------------------- meshes
class Face:
    __slots__ = ("pts", "material", "chart", "uv0")

    def __init__(self, pts, material, chart, uv0):
        self.pts, self.material, self.chart, self.uv0 = pts, material, chart, uv0


class MeshBuilder:
    """Planar convex faces of one object (one glTF mesh, one node)."""

    def __init__(self, name):
        self.name = name
        self.faces = []

    def face(self, pts, material, facing=None, chart=None, uv0=None):
        pts = [tuple(float(c) for c in p) for p in pts]
        if facing is not None and vdot(newell(pts), facing) < 0.0:
            pts = pts[::-1]
            if uv0 is not None:
                uv0 = uv0[::-1]
        if chart is None:
            chart = ("face", len(self.faces))
        self.faces.append(Face(pts, material, chart, uv0))

    def slab(self, axis, ur, vr, wr, material, holes=(), top_materials=None, tag="slab"):
        """A closed solid box with rectangular through-holes, faces outward.

        axis 'x' or 'z' is the slab's length direction U; V is +Y; W the remaining horizontal
        axis. ur, vr, wr are (min, max) world coordinates along U, V, W. holes are
        (u0, u1, v0, v1) rectangles through the whole thickness (a hole may touch the bottom,
        as a doorway does). top_materials: [(u_split, material), ...] splits the top face
        (v = vr[1]) at the given u values; each piece up to its u_split gets that material.
        Coplanar pieces of one side share one lightmap chart."""
        U = (1.0, 0.0, 0.0) if axis == "x" else (0.0, 0.0, 1.0)
        W = (0.0, 0.0, 1.0) if axis == "x" else (1.0, 0.0, 0.0)
        Y = (0.0, 1.0, 0.0)
        (u0, u1), (v0, v1), (w0, w1) = ur, vr, wr

        def P(u, v, w):
            return vadd(vadd(vmul(U, u), vmul(Y, v)), vmul(W, w))

        for h in holes:
            assert u0 < h[0] < h[1] < u1 and v0 <= h[2] < h[3] < v1, (tag, h)
        # The two big sides, minus the holes.
        for w, sgn, side in ((w0, -1.0, "w0"), (w1, 1.0, "w1")):
            for a, b, c, d in rect_minus_holes(u0, u1, v0, v1, holes):
                self.face([P(a, c, w), P(b, c, w), P(b, d, w), P(a, d, w)], material,
                          facing=vmul(W, sgn), chart=(tag, side))
        # Top: optionally split into materials.
        pieces = []
        start = u0
        for split, mat in (top_materials or [(u1, material)]):
            pieces.append((start, min(split, u1), mat))
            start = split
        for a, b, mat in pieces:
            self.face([P(a, v1, w0), P(b, v1, w0), P(b, v1, w1), P(a, v1, w1)], mat,
                      facing=Y, chart=(tag, "top"))
        # Bottom, minus holes that reach it (doorways).
        for a, b in interval_minus(u0, u1, [(h[0], h[1]) for h in holes if h[2] <= v0]):
            self.face([P(a, v0, w0), P(b, v0, w0), P(b, v0, w1), P(a, v0, w1)], material,
                      facing=vmul(Y, -1.0), chart=(tag, "bottom"))
        # Ends.
        for u, sgn, side in ((u0, -1.0, "u0"), (u1, 1.0, "u1")):
            self.face([P(u, v0, w0), P(u, v1, w0), P(u, v1, w1), P(u, v0, w1)], material,
                      facing=vmul(U, sgn), chart=(tag, side))
        # Hole reveals, facing into the hole.
        for k, (a, b, c, d) in enumerate(holes):
            lo = max(c, v0)
            for u, sgn, side in ((a, 1.0, "left"), (b, -1.0, "right")):
                self.face([P(u, lo, w0), P(u, d, w0), P(u, d, w1), P(u, lo, w1)], material,
                          facing=vmul(U, sgn), chart=(tag, "hole", k, side))
            self.face([P(a, d, w0), P(b, d, w0), P(b, d, w1), P(a, d, w1)], material,
                      facing=vmul(Y, -1.0), chart=(tag, "hole", k, "top"))
            if c > v0:
                self.face([P(a, c, w0), P(b, c, w0), P(b, c, w1), P(a, c, w1)], material,
                          facing=Y, chart=(tag, "hole", k, "sill"))

    def box(self, lo, hi, material, tag="box"):
        self.slab("x", (lo[0], hi[0]), (lo[1], hi[1]), (lo[2], hi[2]), material, tag=tag)

    def cavity(self, lo, hi, material, tag="cavity"):
        """A sealed void: a box whose faces point into it (to be put inside a solid). Rays
        from inside see only front faces, so a ray test alone takes the void for open space."""
        first = len(self.faces)
        self.box(lo, hi, material, tag=tag)
        for f in self.faces[first:]:
            f.pts = f.pts[::-1]
            if f.uv0 is not None:
                f.uv0 = f.uv0[::-1]

    def prism(self, center, radius, y0, y1, sides, material):
        """A closed vertical prism (a faceted cylinder), faces outward."""
        ring = []
        for i in range(sides):
            a = 2.0 * math.pi * (i + 0.5) / sides
            ring.append((center[0] + radius * math.cos(a), center[2] + radius * math.sin(a)))
        for i in range(sides):
            (xa, za), (xb, zb) = ring[i], ring[(i + 1) % sides]
            out = (0.5 * (xa + xb) - center[0], 0.0, 0.5 * (za + zb) - center[2])
            self.face([(xa, y0, za), (xb, y0, zb), (xb, y1, zb), (xa, y1, za)], material,
                      facing=out)
        self.face([(x, y1, z) for x, z in ring], material, facing=(0.0, 1.0, 0.0))
        self.face([(x, y0, z) for x, z in ring], material, facing=(0.0, -1.0, 0.0))


def interval_minus(a, b, cuts):
    """[a, b] minus the union of the open intervals in cuts, as sorted intervals."""
    out, start = [], a
    for c0, c1 in sorted(cuts):
        if c0 > start:
            out.append((start, c0))
        start = max(start, c1)
    if start < b:
        out.append((start, b))
    return out


def rect_minus_holes(u0, u1, v0, v1, holes):
    """[u0,u1] x [v0,v1] minus rectangular holes, as rectangles (a, b, c, d) in horizontal
    bands (merged vertically where the band's pieces are the same)."""
    vs = sorted({v0, v1} | {min(max(h[2], v0), v1) for h in holes}
                | {min(max(h[3], v0), v1) for h in holes})
    bands = []
    for c, d in zip(vs, vs[1:]):
        cover = [(h[0], h[1]) for h in holes if h[2] <= c and h[3] >= d]
        pieces = interval_minus(u0, u1, cover)
        if bands and bands[-1][2] == pieces and bands[-1][1] == c:
            bands[-1][1] = d
        else:
            bands.append([c, d, pieces])
    return [(a, b, c, d) for c, d, pieces in bands for a, b in pieces]


# ----------------------------------------------------------------------------- lightmap UVs
def convex_hull_2d(points):
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def chart_frame(points, n):
    """In-plane axes (t, b), b = n x t, of the smallest-area bounding rectangle of the
    points (rotating calipers over the hull's edges). Ties prefer b pointing up (walls stay
    upright in the lightmap), then t along +X."""
    a = (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 1.0, 0.0)
    e1 = vnorm(vcross(a, n))
    e2 = vcross(n, e1)
    hull = convex_hull_2d([(round(vdot(p, e1), 9), round(vdot(p, e2), 9)) for p in points])
    candidates = []
    for i in range(len(hull)):
        dx, dy = hull[(i + 1) % len(hull)][0] - hull[i][0], hull[(i + 1) % len(hull)][1] - hull[i][1]
        length = math.hypot(dx, dy)
        if length < 1e-9:
            continue
        t = vnorm(vadd(vmul(e1, dx / length), vmul(e2, dy / length)))
        for _ in range(4):
            b = vcross(n, t)
            us = [vdot(p, t) for p in points]
            ws = [vdot(p, b) for p in points]
            area = (max(us) - min(us)) * (max(ws) - min(ws))
            candidates.append((area, t, b))
            t = b
    best_area = min(c[0] for c in candidates)
    ties = [c for c in candidates if c[0] <= best_area * (1.0 + 1e-6) + 1e-12]
    ties.sort(key=lambda c: (round(c[2][1], 6), round(c[1][0], 6), round(-c[1][2], 6)),
              reverse=True)
    return ties[0][1], ties[0][2]


def shelf_pack(sizes, scale, gutter):
    """Places rectangles (w, h) x scale in rows inside [0,1]^2, `gutter` apart and from the
    border. Returns the lower-left corners or None when they do not fit."""
    limit = 1.0 - gutter + 1e-12
    order = sorted(range(len(sizes)), key=lambda i: (-sizes[i][1], -sizes[i][0], i))
    x, y, row, pos = gutter, gutter, 0.0, [None] * len(sizes)
    for i in order:
        w, h = sizes[i][0] * scale, sizes[i][1] * scale
        if gutter + w > limit or gutter + h > limit:
            return None
        if x + w > limit:
            y, x, row = y + row + gutter, gutter, 0.0
        pos[i] = (x, y)
        x += w + gutter
        row = max(row, h)
    if y + row > limit:
        return None
    return pos


def pack_charts(sizes, gutter=GUTTER):
    """Largest common scale (and placement, rotation flags) that fits the charts (w, h) in
    metres into [0,1]^2. Tries each chart as given, all landscape, all portrait, packed in
    rows or in columns; keeps the best. Returns (scale, [(x, y, rotated)])."""
    best = None
    for policy in ("given", "landscape", "portrait"):
        rot = []
        for w, h in sizes:
            rot.append((policy == "landscape" and h > w) or (policy == "portrait" and w > h))
        rs = [(h, w) if r else (w, h) for (w, h), r in zip(sizes, rot)]
        for columns in (False, True):
            ps = [(h, w) for w, h in rs] if columns else rs
            hi = (1.0 - 2.0 * gutter) / max(max(w, h) for w, h in ps)
            if shelf_pack(ps, hi, gutter) is not None:
                lo = hi
            else:
                lo = 0.0
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    if shelf_pack(ps, mid, gutter) is not None:
                        lo = mid
                    else:
                        hi = mid
            pos = shelf_pack(ps, lo, gutter)
            if pos is None or lo <= 0.0:
                continue
            if columns:
                pos = [(y, x) for x, y in pos]
            if best is None or lo > best[0] * (1.0 + 1e-9):
                best = (lo, [(p[0], p[1], r) for p, r in zip(pos, rot)])
    assert best is not None, "charts do not fit"
    return best


def lightmap_uvs(faces):
    """Per face, per vertex: (uv0_metres, uv1). One chart per chart key (coplanar faces)."""
    keys = []
    members = {}
    for i, f in enumerate(faces):
        if f.chart not in members:
            keys.append(f.chart)
            members[f.chart] = []
        members[f.chart].append(i)
    frames, sizes = [], []
    for key in keys:
        n = (0.0, 0.0, 0.0)
        pts = []
        for i in members[key]:
            n = vadd(n, newell(faces[i].pts))
            pts.extend(faces[i].pts)
        n = vnorm(n)
        for p in pts:  # a chart must be planar
            assert abs(vdot(vsub(p, pts[0]), n)) < 5e-3, key
        t, b = chart_frame(pts, n)
        us = [vdot(p, t) for p in pts]
        vs = [-vdot(p, b) for p in pts]
        frames.append((t, b, min(us), min(vs)))
        sizes.append((max(us) - min(us), max(vs) - min(vs)))
    scale, place = pack_charts(sizes)
    # Centre the layout in the unit square.
    xs0 = min(place[k][0] for k in range(len(keys)))
    ys0 = min(place[k][1] for k in range(len(keys)))
    xs1 = max(place[k][0] + scale * (sizes[k][1] if place[k][2] else sizes[k][0]) for k in range(len(keys)))
    ys1 = max(place[k][1] + scale * (sizes[k][0] if place[k][2] else sizes[k][1]) for k in range(len(keys)))
    dx, dy = 0.5 - 0.5 * (xs0 + xs1), 0.5 - 0.5 * (ys0 + ys1)
    out = [None] * len(faces)
    for k, key in enumerate(keys):
        t, b, umin, vmin = frames[k]
        w = sizes[k][0]
        x, y, rotated = place[k]
        for i in members[key]:
            uv0, uv1 = [], []
            for p in faces[i].pts:
                u, v = vdot(p, t) - umin, -vdot(p, b) - vmin
                uv0.append((u, v))
                if rotated:  # a quarter turn: (u, v) -> (v, w - u), not a mirror
                    u, v = v, w - u
                uv1.append((x + dx + u * scale, y + dy + v * scale))
            out[i] = (uv0, uv1)
    return out


# ----------------------------------------------------------------------------- glTF writer
class Gltf:
    def __init__(self, name, index_type=5123):
        self.name = name
        self.index_type = index_type  # 5123 unsigned short, 5125 unsigned int
        self.buf = bytearray()
        self.views, self.accessors, self.meshes, self.materials = [], [], [], []
        self.material_index = {}
        self.nodes, self.cameras, self.lights = [], [], []
        self.images, self.textures, self.samplers = [], [], []
        self.extensions = set()
        self.files = {}  # extra files (PNG) name -> bytes
        self.stats = {}  # node name -> triangle count

    def _view(self, data, target):
        while len(self.buf) % 4:
            self.buf.append(0)
        self.views.append({"buffer": 0, "byteOffset": len(self.buf), "byteLength": len(data),
                           "target": target})
        self.buf.extend(data)
        return len(self.views) - 1

    def _accessor(self, data, target, comp, count, typ, minmax=None):
        acc = {"bufferView": self._view(data, target), "componentType": comp, "count": count,
               "type": typ}
        if minmax:
            acc["min"], acc["max"] = minmax
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def material(self, name, color, alpha=1.0, **kw):
        if name in self.material_index:
            return name
        m = {"name": name, "pbrMetallicRoughness": {
            "baseColorFactor": [rnd(c, 6) for c in color] + [alpha],
            "metallicFactor": 0.0, "roughnessFactor": 1.0}}
        if "texture" in kw:
            m["pbrMetallicRoughness"]["baseColorTexture"] = {"index": kw["texture"], "texCoord": 0}
        if "emissive" in kw:
            m["emissiveFactor"] = [rnd(c, 7) for c in kw["emissive"]]
            if kw.get("strength", 1.0) != 1.0:
                m["extensions"] = {"KHR_materials_emissive_strength":
                                   {"emissiveStrength": kw["strength"]}}
                self.extensions.add("KHR_materials_emissive_strength")
        if "alphaMode" in kw:
            m["alphaMode"] = kw["alphaMode"]
            if kw["alphaMode"] == "MASK":
                m["alphaCutoff"] = kw.get("alphaCutoff", 0.5)
        if kw.get("doubleSided"):
            m["doubleSided"] = True
        self.material_index[name] = len(self.materials)
        self.materials.append(m)
        return name

    def texture_png(self, filename, png_bytes):
        self.files[filename] = png_bytes
        if not self.samplers:
            self.samplers.append({"magFilter": 9729, "minFilter": 9987, "wrapS": 33071,
                                  "wrapT": 33071})
        self.images.append({"uri": filename, "mimeType": "image/png"})
        self.textures.append({"source": len(self.images) - 1, "sampler": 0})
        return len(self.textures) - 1

    def mesh(self, mb):
        uvs = lightmap_uvs(mb.faces)
        mats = []
        for f in mb.faces:
            if f.material not in mats:
                mats.append(f.material)
        prims, tris = [], 0
        for mat in mats:
            P, N, T0, T1, idx = [], [], [], [], []
            for i, f in enumerate(mb.faces):
                if f.material != mat:
                    continue
                n = vnorm(newell(f.pts))
                uv0, uv1 = uvs[i]
                if f.uv0 is not None:
                    uv0 = f.uv0
                base = len(P)
                for k, p in enumerate(f.pts):
                    P.append(tuple(rnd(c, 7) for c in p))
                    N.append(n)
                    T0.append(uv0[k])
                    T1.append(uv1[k])
                for k in range(1, len(f.pts) - 1):
                    idx.extend((base, base + k, base + k + 1))
            tris += len(idx) // 3
            pf = [tuple(f32(c) for c in p) for p in P]
            mn = [min(p[k] for p in pf) for k in range(3)]
            mx = [max(p[k] for p in pf) for k in range(3)]
            attrs = {
                "POSITION": self._accessor(b"".join(struct.pack("<3f", *p) for p in P), 34962,
                                           5126, len(P), "VEC3", (mn, mx)),
                "NORMAL": self._accessor(b"".join(struct.pack("<3f", *n) for n in N), 34962,
                                         5126, len(N), "VEC3"),
                "TEXCOORD_0": self._accessor(b"".join(struct.pack("<2f", *t) for t in T0),
                                             34962, 5126, len(T0), "VEC2"),
                "TEXCOORD_1": self._accessor(b"".join(struct.pack("<2f", *t) for t in T1),
                                             34962, 5126, len(T1), "VEC2"),
            }
            fmt = "<%dH" if self.index_type == 5123 else "<%dI"
            assert self.index_type != 5123 or len(P) < 65536
            ia = self._accessor(struct.pack(fmt % len(idx), *idx), 34963, self.index_type,
                                len(idx), "SCALAR")
            prims.append({"attributes": attrs, "indices": ia,
                          "material": self.material_index[mat]})
        self.meshes.append({"name": mb.name, "primitives": prims})
        self.stats[mb.name] = tris
        return len(self.meshes) - 1

    def node(self, name, mb=None, parent=None, translation=None, rotation=None, extras=None,
             camera=None, light=None):
        n = {"name": name}
        if mb is not None:
            n["mesh"] = self.mesh(mb)
        if translation is not None:
            n["translation"] = [rnd(c) for c in translation]
        if rotation is not None:
            n["rotation"] = rotation
        if camera is not None:
            self.cameras.append(camera)
            n["camera"] = len(self.cameras) - 1
        if light is not None:
            self.lights.append(light)
            n["extensions"] = {"KHR_lights_punctual": {"light": len(self.lights) - 1}}
            self.extensions.add("KHR_lights_punctual")
        if extras is not None:
            n["extras"] = extras
        n["_parent"] = parent
        self.nodes.append(n)
        return len(self.nodes) - 1

    def write(self, out_dir, scene_extras, generator):
        roots = []
        for i, n in enumerate(self.nodes):
            parent = n.pop("_parent")
            if parent is None:
                roots.append(i)
            else:
                self.nodes[parent].setdefault("children", []).append(i)
        while len(self.buf) % 4:
            self.buf.append(0)
        g = {"asset": {"version": "2.0", "generator": generator}}
        if self.extensions:
            g["extensionsUsed"] = sorted(self.extensions)
        g["scene"] = 0
        g["scenes"] = [{"name": self.name, "nodes": roots, "extras": scene_extras}]
        g["nodes"] = self.nodes
        g["meshes"] = self.meshes
        g["materials"] = self.materials
        for key, val in (("textures", self.textures), ("images", self.images),
                         ("samplers", self.samplers), ("cameras", self.cameras)):
            if val:
                g[key] = val
        g["accessors"] = self.accessors
        g["bufferViews"] = self.views
        g["buffers"] = [{"uri": self.name + ".bin", "byteLength": len(self.buf)}]
        if self.lights:
            g["extensions"] = {"KHR_lights_punctual": {"lights": self.lights}}
        files = dict(self.files)
        files[self.name + ".bin"] = bytes(self.buf)
        files[self.name + ".gltf"] = (json.dumps(g, indent=1) + "\n").encode()
        os.makedirs(out_dir, exist_ok=True)
        for fname, data in files.items():  # temporary file + rename
            path = os.path.join(out_dir, fname)
            with open(path + ".tmp", "wb") as fh:
                fh.write(data)
            os.replace(path + ".tmp", path)
        total = sum(self.stats.values())
        print("%s.gltf: %d nodes, %d meshes, %d triangles, %d bytes of buffer"
              % (self.name, len(self.nodes), len(self.meshes), total, len(self.buf)))


def perspective(yfov, aspect, znear=0.05):
    return {"type": "perspective", "perspective": {"yfov": rnd(yfov, 9), "aspectRatio": aspect,
                                                   "znear": znear}}


# ----------------------------------------------------------------------------- PNG
def png_rgba(width, height, rows):
    def chunk(tag, data):
        return (struct.pack(">I", len(data)) + tag + data
                + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))

    raw = b"".join(b"\x00" + bytes(r) for r in rows)
    return (b"\x89PNG\r\n\x1a\n"
            + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def leaves_png(size=128, seed=12345):
    """Leaf blobs on a transparent background, inside a round canopy silhouette: RGBA8, sRGB
    colours, alpha = leaf coverage (4x4 supersampled); transparent texels keep a dark green so
    that filtering does not bleed black into the leaves' edges."""
    state = [seed]

    def rand():  # 32-bit LCG (Numerical Recipes constants): deterministic everywhere
        state[0] = (1664525 * state[0] + 1013904223) & 0xFFFFFFFF
        return state[0] / 4294967296.0

    leaves = []
    c = size * 0.5
    for _ in range(150):
        r = (size * 0.44) * math.sqrt(rand())
        a = 2.0 * math.pi * rand()
        cx, cy = c + r * math.cos(a), c + r * math.sin(a)
        ang = 2.0 * math.pi * rand()
        length = size * (0.055 + 0.05 * rand())
        width = length * (0.35 + 0.15 * rand())
        shade = 0.7 + 0.5 * rand()
        col = (min(255, int(52 * shade)), min(255, int(112 * shade)), min(255, int(34 * shade)))
        leaves.append((cx, cy, math.cos(ang), math.sin(ang), length, width, col))
    # Later leaves lie on top. Bucket leaves by cell so the rasterization stays quick.
    cell = 16
    buckets = {}
    for li, (cx, cy, _, _, length, _, _) in enumerate(leaves):
        for gx in range(int((cx - length) // cell), int((cx + length) // cell) + 1):
            for gy in range(int((cy - length) // cell), int((cy + length) // cell) + 1):
                buckets.setdefault((gx, gy), []).append(li)
    rows = []
    for y in range(size):
        row = bytearray()
        for x in range(size):
            cand = buckets.get((x // cell, y // cell), [])
            hits, acc = 0, [0, 0, 0]
            for sy in range(4):
                for sx in range(4):
                    px, py = x + (sx + 0.5) / 4.0, y + (sy + 0.5) / 4.0
                    top = None
                    for li in cand:
                        cx, cy, ca, sa, length, width, col = leaves[li]
                        du, dv = (px - cx) * ca + (py - cy) * sa, -(px - cx) * sa + (py - cy) * ca
                        t = du / length
                        if abs(t) < 1.0 and abs(dv) < width * (1.0 - t * t):
                            top = col
                            if abs(dv) < 0.35:  # midrib
                                top = (int(col[0] * 0.7), int(col[1] * 0.7), int(col[2] * 0.7))
                    if top is not None:
                        hits += 1
                        for k in range(3):
                            acc[k] += top[k]
            if hits:
                row.extend((acc[0] // hits, acc[1] // hits, acc[2] // hits, hits * 255 // 16))
            else:
                row.extend((40, 80, 28, 0))
        rows.append(row)
    return png_rgba(size, size, rows)


# ----------------------------------------------------------------------------- scene 1
def cornell_box(out_dir):
    """The Cornell box from the Cornell Program of Computer Graphics' published measurements
    (mm; converted to metres). Quads face into the box; the boxes' faces face outward."""
    quads = [  # name, material, vertices (mm), facing: 'in' (towards the room centre) / box
        ("floor", "white", [(552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2)], "in"),
        ("ceiling", "white", [(556.0, 548.8, 0), (556.0, 548.8, 559.2), (0, 548.8, 559.2),
                              (0, 548.8, 0)], "in"),
        ("back", "white", [(549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2),
                           (556.0, 548.8, 559.2)], "in"),
        ("right_green", "green", [(0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2)],
         "in"),
        ("left_red", "red", [(552.8, 0, 0), (549.6, 0, 559.2), (556.0, 548.8, 559.2),
                             (556.0, 548.8, 0)], "in"),
        # The light, lowered 1 mm below the ceiling (548.8 -> 547.8), facing down.
        ("light", "light", [(343.0, 547.8, 227.0), (343.0, 547.8, 332.0), (213.0, 547.8, 332.0),
                            (213.0, 547.8, 227.0)], "in"),
        ("short_top", "white", [(130, 165, 65), (82, 165, 225), (240, 165, 272), (290, 165, 114)],
         "short"),
        ("short_1", "white", [(290, 0, 114), (290, 165, 114), (240, 165, 272), (240, 0, 272)],
         "short"),
        ("short_2", "white", [(130, 0, 65), (130, 165, 65), (290, 165, 114), (290, 0, 114)],
         "short"),
        ("short_3", "white", [(82, 0, 225), (82, 165, 225), (130, 165, 65), (130, 0, 65)],
         "short"),
        ("short_4", "white", [(240, 0, 272), (240, 165, 272), (82, 165, 225), (82, 0, 225)],
         "short"),
        ("tall_top", "white", [(423, 330, 247), (265, 330, 296), (314, 330, 456),
                               (472, 330, 406)], "tall"),
        ("tall_1", "white", [(423, 0, 247), (423, 330, 247), (472, 330, 406), (472, 0, 406)],
         "tall"),
        ("tall_2", "white", [(472, 0, 406), (472, 330, 406), (314, 330, 456), (314, 0, 456)],
         "tall"),
        ("tall_3", "white", [(314, 0, 456), (314, 330, 456), (265, 330, 296), (265, 0, 296)],
         "tall"),
        ("tall_4", "white", [(265, 0, 296), (265, 330, 296), (423, 330, 247), (423, 0, 247)],
         "tall"),
    ]
    room_c = (278.0, 274.4, 279.6)
    box_c = {"short": (186.0, 82.5, 168.5), "tall": (368.5, 165.0, 351.5)}
    g = Gltf("cornell_box")
    g.material("white", (0.725, 0.71, 0.68))
    g.material("red", (0.63, 0.065, 0.05))
    g.material("green", (0.14, 0.45, 0.091))
    g.material("light", (0.78, 0.78, 0.78), emissive=(1.0, 12.0 / 17.0, 4.0 / 17.0),
               strength=17.0)
    for name, mat, pts_mm, where in quads:
        cen = tuple(sum(p[k] for p in pts_mm) / 4.0 for k in range(3))
        facing = vsub(room_c, cen) if where == "in" else vsub(cen, box_c[where])
        mb = MeshBuilder(name)
        mb.face([tuple(c / 1000.0 for c in p) for p in pts_mm], mat, facing=facing)
        g.node(name, mb)
    # Camera: (278, 273, -800) mm looking +Z; 25 mm film, 35 mm focal length.
    g.node("camera", translation=(0.278, 0.273, -0.8), rotation=look_rotation((0, 0, 1)),
           camera=perspective(2.0 * math.atan(12.5 / 35.0), 1.0, 0.01))
    g.write(out_dir, {"kiln": {"sky": {"color": [0.0, 0.0, 0.0]}}}, "kiln tools/make_scenes.py")
    return g


# ----------------------------------------------------------------------------- scenes 2, 2b
# Two rooms side by side along +X, each 4 x 3 x 4 m inside, walls 0.25 m, floor/ceiling slabs
# 0.25 m. Room A: x in [0, 4]; shared wall x in [4, 4 + s] (s = 0.25 in two_rooms, 0.05 in
# two_rooms_thin); room B: x in [4 + s, 8 + s]; z in [0, 4]; floor top y = 0, ceiling
# underside y = 3.
TR_T = 0.25
TR_THIN = 0.05  # two_rooms_thin's shared wall
TR_ROOM_A = ((0.0, 4.0), (0.0, 3.0), (0.0, 4.0))
TR_WINDOW = (2.4, 3.6, 0.9, 2.1)  # south wall (z in [-0.25, 0]): x0, x1, y0, y1
TR_DOOR = (2.8, 3.8, 2.1)  # shared wall: z0, z1, top
TR_SUN = sun_direction(40.0, 20.0)


def two_rooms(out_dir, name="two_rooms", shared=TR_T):
    """two_rooms (shared wall TR_T thick) or, with another name and `shared`, the same rooms
    with a thinner shared wall; room B and everything in it move with the wall's far face."""
    g = Gltf(name)
    g.material("wall_white", (0.7, 0.7, 0.68))
    g.material("ceiling_white", (0.75, 0.75, 0.73))
    g.material("floor_terracotta", (0.62, 0.32, 0.2))
    g.material("floor_grey", (0.5, 0.5, 0.5))
    g.material("concrete", (0.45, 0.45, 0.45))
    g.material("wood", (0.45, 0.3, 0.18))
    g.material("cabinet_blue", (0.25, 0.35, 0.55))
    g.material("dynamic_orange", (0.8, 0.45, 0.1))
    t = TR_T
    room_b = ((4.0 + shared, 8.0 + shared), (0.0, 3.0), (0.0, 4.0))
    x_end = room_b[0][1]
    # Walls reach halfway into the floor and ceiling slabs and into the walls they meet, so
    # that no two solids share a face (no coplanar overlaps anywhere); the 0.125 m notch this
    # leaves at the four outer corners is outside the rooms.
    wy = (-t / 2.0, 3.0 + t / 2.0)
    long_x = (-t / 2.0, x_end + t + t / 2.0)
    side_z = (-t / 2.0, 4.0 + t / 2.0)
    over = 0.1  # floor and ceiling overhang the walls' outer faces
    fx, fz = (-t - over, x_end + t + over), (-t - over, 4.0 + t + over)

    mb = MeshBuilder("floor")
    mb.slab("x", fx, (-t, 0.0), fz, "concrete",
            top_materials=[(4.0 + shared / 2.0, "floor_terracotta"), (fx[1], "floor_grey")])
    g.node("floor", mb)
    mb = MeshBuilder("ceiling")
    mb.slab("x", fx, (3.0, 3.0 + t), fz, "ceiling_white")
    g.node("ceiling", mb)
    wx0, wx1, wy0, wy1 = TR_WINDOW
    mb = MeshBuilder("wall_south")
    mb.slab("x", long_x, wy, (-t, 0.0), "wall_white", holes=[(wx0, wx1, wy0, wy1)])
    g.node("wall_south", mb)
    mb = MeshBuilder("wall_north")
    mb.slab("x", long_x, wy, (4.0, 4.0 + t), "wall_white")
    g.node("wall_north", mb)
    mb = MeshBuilder("wall_west")
    mb.slab("z", side_z, wy, (-t, 0.0), "wall_white")
    g.node("wall_west", mb)
    mb = MeshBuilder("wall_east")
    mb.slab("z", side_z, wy, (x_end, x_end + t), "wall_white")
    g.node("wall_east", mb)
    dz0, dz1, dtop = TR_DOOR
    mb = MeshBuilder("wall_shared")
    mb.slab("z", side_z, wy, (4.0, 4.0 + shared), "wall_white",
            holes=[(dz0, dz1, wy[0], dtop)])
    g.node("wall_shared", mb)

    # Furniture: solid boxes sunk 1 cm into the floor (no face shared with the floor).
    furniture = [  # name, material, local box, translation, rotation about Y (degrees)
        ("table_A", "wood", ((-0.5, -0.01, -0.35), (0.5, 0.45, 0.35)), (1.0, 0.0, 3.0), 15.0),
        ("cabinet_B", "cabinet_blue", ((-0.175, -0.01, -0.5), (0.175, 1.8, 0.5)),
         (x_end - 0.225, 0.0, 1.5), 0.0),
    ]
    solids = []  # world-space boxes as 8 corners, for the clearance checks below
    for name, mat, (lo, hi), tr, rot in furniture:
        mb = MeshBuilder(name)
        mb.box(lo, hi, mat)
        g.node(name, mb, translation=tr, rotation=quat_y(rot) if rot else None)
        solids.append((name, lo, hi, tr, rot))
    # A small dynamic box in room B: lit by probes, no lightmap, not part of the static scene.
    mb = MeshBuilder("dynamic_box")
    mb.box((-0.15, 0.0, -0.15), (0.15, 0.3, 0.15), "dynamic_orange")
    box_at = (room_b[0][0] + 1.75, 0.0, 1.0)
    g.node("dynamic_box", mb, translation=box_at, rotation=quat_y(30.0),
           extras={"kiln": {"static": False}})
    solids.append(("dynamic_box", (-0.15, 0.0, -0.15), (0.15, 0.3, 0.15), box_at, 30.0))

    # Probes: 3 x 2 x 3 per room, stored relative to the group node's translation.
    origin = (0.5 * x_end, 1.5, 2.0)
    probes = []
    for (rx, _, _) in (TR_ROOM_A, room_b):
        for ox in (0.75, 2.0, 3.25):
            for y in (0.9, 2.1):
                for z in (0.75, 2.0, 3.25):
                    probes.append((rx[0] + ox, y, z))
    for p in probes:  # >= 0.3 m from the room's surfaces and from every block
        room = TR_ROOM_A if p[0] < 4.0 else room_b
        assert all(room[k][0] + 0.3 <= p[k] <= room[k][1] - 0.3 for k in range(3)), p
        for name, lo, hi, tr, rot in solids:
            q = vsub(p, tr)
            q = rotate_y(q, -rot)
            d = vlen(tuple(max(lo[k] - q[k], 0.0, q[k] - hi[k]) for k in range(3)))
            assert d >= 0.3, (p, name, d)
    local = [[rnd(c, 6) for c in vsub(p, origin)] for p in probes]
    g.node("probe_group", translation=origin, extras={"kiln": {"probes": local}})

    # Sun through the window of room A; check where the patch lands.
    sun = TR_SUN
    sun_patch(sun)
    g.node("sun", rotation=look_rotation(sun),
           light={"name": "sun", "type": "directional", "color": [1.0, 0.95, 0.85],
                  "intensity": 10.0, "extras": {"kiln": {"mode": "baked", "shadowAngle": 0.5}}})
    g.node("camera", translation=(0.4, 1.7, 3.6),
           rotation=look_rotation(vsub((4.0, 0.6, 1.4), (0.4, 1.7, 3.6))),
           camera=perspective(math.radians(70.0), 16.0 / 9.0))
    g.write(out_dir, {"kiln": {"sky": {"color": [0.3, 0.4, 0.6]}, "lightmapResolution": 8.0,
                               "bounces": 3}}, "kiln tools/make_scenes.py")
    return g


def sun_patch(sun, verbose=False):
    """Traces sun rays through the window (both faces of the wall must be passed) to the
    floor or the shared wall of room A; asserts that none reaches the doorway, so that
    room B gets no direct sun. Returns the floor and shared-wall patch bounds."""
    wx0, wx1, wy0, wy1 = TR_WINDOW
    floor_pts, wall_pts = [], []
    n = 24
    for i in range(n + 1):
        for j in range(n + 1):
            x, y = wx0 + (wx1 - wx0) * i / n, wy0 + (wy1 - wy0) * j / n
            # Entering at the wall's outer face z = -T: where is it at the inner face z = 0?
            s = TR_T / sun[2]
            xi, yi = x + sun[0] * s, y + sun[1] * s
            if not (wx0 <= xi <= wx1 and wy0 <= yi <= wy1):
                continue
            t_floor = -yi / sun[1]
            t_wall = (4.0 - xi) / sun[0]
            if t_floor <= t_wall:
                floor_pts.append((xi + sun[0] * t_floor, sun[2] * t_floor))
            else:
                hit = (yi + sun[1] * t_wall, sun[2] * t_wall)
                assert hit[1] < TR_DOOR[0] - 0.3, hit  # never into the doorway
                wall_pts.append(hit)
    assert floor_pts and wall_pts
    bounds = lambda pts: [(min(p[k] for p in pts), max(p[k] for p in pts)) for k in range(2)]
    return bounds(floor_pts), bounds(wall_pts)


# ----------------------------------------------------------------------------- scene 3
CY_SUN = sun_direction(50.0, 40.0)


def courtyard(out_dir):
    g = Gltf("courtyard", index_type=5125)  # 32-bit indices here (the others use 16-bit)
    g.material("paving", (0.45, 0.43, 0.4))
    g.material("sandstone", (0.7, 0.62, 0.5))
    g.material("plaster", (0.65, 0.65, 0.62))
    g.material("bark", (0.3, 0.22, 0.15))
    g.material("post_grey", (0.35, 0.35, 0.35))
    leaves_tex = g.texture_png("leaves.png", leaves_png())
    g.material("leaves", (1.0, 1.0, 1.0), texture=leaves_tex, alphaMode="MASK",
               alphaCutoff=0.5, doubleSided=True)
    g.material("awning_red", (0.9, 0.3, 0.2), alpha=0.5, alphaMode="BLEND", doubleSided=True)

    mb = MeshBuilder("ground")
    mb.face([(-10.0, 0.0, -10.0), (10.0, 0.0, -10.0), (10.0, 0.0, 10.0), (-10.0, 0.0, 10.0)],
            "paving", facing=(0.0, 1.0, 0.0))
    g.node("ground", mb)
    blocks = [  # name, x range, z range, height, material; sunk 0.1 m into the ground
        ("block_north", (-9.5, 3.5), (6.5, 9.5), 7.0, "sandstone"),
        ("block_east", (6.5, 9.5), (-5.0, 9.5), 5.0, "plaster"),
        ("block_south", (-4.0, 9.5), (-9.5, -7.0), 4.0, "sandstone"),
        ("block_west", (-9.5, -6.5), (-9.5, 2.5), 6.0, "plaster"),
    ]
    for name, xr, zr, h, mat in blocks:
        mb = MeshBuilder(name)
        mb.box((xr[0], -0.1, zr[0]), (xr[1], h, zr[1]), mat)
        g.node(name, mb)

    # Trees: a parent node per tree (its transform places the tree), an octagonal trunk and
    # foliage of three crossed vertical cards and one horizontal card (cutout leaves).
    for name, pos, rot in (("tree_1", (2.5, 0.0, -2.5), 0.0), ("tree_2", (-1.5, 0.0, 3.5), 20.0)):
        parent = g.node(name, translation=pos, rotation=quat_y(rot))
        mb = MeshBuilder(name + "_trunk")
        mb.prism((0.0, 0.0, 0.0), 0.15, -0.05, 3.2, 8, "bark")
        g.node(name + "_trunk", mb, parent=parent)
        mb = MeshBuilder(name + "_foliage")
        half, y0, y1 = 1.5, 2.0, 5.0
        for k in range(3):
            a = math.radians(60.0 * k)
            d = (math.cos(a) * half, 0.0, -math.sin(a) * half)
            pts = [(-d[0], y0, -d[2]), (d[0], y0, d[2]), (d[0], y1, d[2]), (-d[0], y1, -d[2])]
            mb.face(pts, "leaves", uv0=[(0.0, 1.0), (1.0, 1.0), (1.0, 0.0), (0.0, 0.0)])
        yc = 3.5
        mb.face([(-half, yc, half), (half, yc, half), (half, yc, -half), (-half, yc, -half)],
                "leaves", facing=(0.0, 1.0, 0.0),
                uv0=[(0.0, 1.0), (1.0, 1.0), (1.0, 0.0), (0.0, 0.0)])
        g.node(name + "_foliage", mb, parent=parent)

    # Awning: a flat semi-transparent sheet on four posts (which pierce it by 2 cm), with a
    # baked point lamp under it.
    group = g.node("awning_group", translation=(-2.0, 0.0, -1.5))
    hx, hz, ya = 1.5, 1.5, 2.6
    mb = MeshBuilder("awning")
    mb.face([(-hx, ya, -hz), (hx, ya, -hz), (hx, ya, hz), (-hx, ya, hz)], "awning_red",
            facing=(0.0, 1.0, 0.0))
    g.node("awning", mb, parent=group)
    for k, (sx, sz) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
        cx, cz = sx * (hx - 0.1), sz * (hz - 0.1)
        mb = MeshBuilder("awning_post_%d" % (k + 1))
        mb.box((cx - 0.05, -0.05, cz - 0.05), (cx + 0.05, ya + 0.02, cz + 0.05), "post_grey")
        g.node("awning_post_%d" % (k + 1), mb, parent=group)
    g.node("awning_lamp", parent=group, translation=(0.0, 2.3, 0.0),
           light={"name": "awning_lamp", "type": "point", "color": [1.0, 0.75, 0.45],
                  "intensity": 4.0, "range": 10.0,
                  "extras": {"kiln": {"mode": "baked", "shadowRadius": 0.05}}})
    g.node("sun", rotation=look_rotation(CY_SUN),
           light={"name": "sun", "type": "directional", "color": [1.0, 0.95, 0.85],
                  "intensity": 5.0, "extras": {"kiln": {"mode": "baked", "shadowAngle": 1.0}}})
    g.node("camera", translation=(5.0, 11.0, -13.0),
           rotation=look_rotation(vsub((-1.0, 0.5, 0.5), (5.0, 11.0, -13.0))),
           camera=perspective(math.radians(60.0), 16.0 / 9.0))
    g.write(out_dir, {"kiln": {"sky": {"color": [0.2, 0.28, 0.45]}, "lightmapResolution": 2.0,
                               "bounces": 2}}, "kiln tools/make_scenes.py")
    return g

# The atrium (Crytek Sponza's case, docs/scenes.md): an open court under the sky between two
# arcaded galleries on two floors, a roof over the galleries only, thick outer walls with
# sealed cavities inside them. The court is x in [-5, 5], z in [-2.5, 2.5]; the galleries
# z in [2.5, 5] and [-5, -2.5], floors at y = 0 and 4.3; the roof at y = 8.
AT_SUN = sun_direction(60.0, 30.0)
AT_CAVITIES = [  # (lo, hi) of the sealed voids inside the outer walls
    ((-4.5, 0.5, 5.3), (4.5, 7.5, 5.9)),
    ((-4.5, 0.5, -5.9), (4.5, 7.5, -5.3)),
    ((5.3, 0.5, -4.5), (5.9, 9.0, 4.5)),
    ((-5.9, 0.5, -4.5), (-5.3, 9.0, 4.5)),
]


def atrium(out_dir):
    g = Gltf("atrium")
    g.material("stone", (0.62, 0.58, 0.5))
    g.material("floor_stone", (0.5, 0.47, 0.42))
    g.material("plaster", (0.7, 0.68, 0.62))
    g.material("roof_tiles", (0.45, 0.25, 0.18))

    mb = MeshBuilder("ground")
    mb.box((-6.3, -0.3, -6.3), (6.3, 0.0, 6.3), "floor_stone")
    g.node("ground", mb)
    # Outer walls, 1.2 m thick, each with a sealed cavity inside; the long walls end at the
    # roof, the end walls rise above it.
    walls = [("wall_north", (-6.2, -0.1, 5.0), (6.2, 8.6, 6.2), 0),
             ("wall_south", (-6.2, -0.1, -6.2), (6.2, 8.6, -5.0), 1),
             ("wall_east", (5.0, -0.1, -5.1), (6.2, 10.0, 5.1), 2),
             ("wall_west", (-6.2, -0.1, -5.1), (-5.0, 10.0, 5.1), 3)]
    for name, lo, hi, k in walls:
        mb = MeshBuilder(name)
        mb.box(lo, hi, "plaster")
        mb.cavity(AT_CAVITIES[k][0], AT_CAVITIES[k][1], "plaster")
        g.node(name, mb)
    # Galleries on both long sides: the first floor's slab, the roof, and the arcades (piers
    # on both floors, a parapet between the upper piers).
    piers = (-3.75, -1.25, 1.25, 3.75)
    for side, sgn in (("north", 1.0), ("south", -1.0)):
        def zr(a, b):
            return (min(sgn * a, sgn * b), max(sgn * a, sgn * b))
        z_slab = zr(2.5, 5.1)
        mb = MeshBuilder("gallery_floor_" + side)
        mb.box((-5.1, 4.0, z_slab[0]), (5.1, 4.3, z_slab[1]), "stone")
        g.node("gallery_floor_" + side, mb)
        mb = MeshBuilder("roof_" + side)
        mb.box((-5.1, 8.0, z_slab[0]), (5.1, 8.3, z_slab[1]), "roof_tiles")
        g.node("roof_" + side, mb)
        z_pier = zr(2.5, 3.0)
        for k, x in enumerate(piers):
            mb = MeshBuilder("pier_%s_%d" % (side, k + 1))
            mb.box((x - 0.25, -0.1, z_pier[0]), (x + 0.25, 4.1, z_pier[1]), "stone")
            g.node("pier_%s_%d" % (side, k + 1), mb)
            mb = MeshBuilder("pier_%s_upper_%d" % (side, k + 1))
            mb.box((x - 0.25, 4.2, z_pier[0]), (x + 0.25, 8.1, z_pier[1]), "stone")
            g.node("pier_%s_upper_%d" % (side, k + 1), mb)
        z_par = zr(2.55, 2.95)
        ends = [-5.1] + [c for x in piers for c in (x - 0.3, x + 0.3)] + [5.1]
        for k in range(0, len(ends), 2):
            mb = MeshBuilder("parapet_%s_%d" % (side, k // 2 + 1))
            mb.box((ends[k], 4.2, z_par[0]), (ends[k + 1], 5.2, z_par[1]), "stone")
            g.node("parapet_%s_%d" % (side, k // 2 + 1), mb)

    # Eight hand-placed probes (the user's group): the court at 1 m and the upper galleries.
    probes = [(x, 1.0, z) for x in (-2.5, 2.5) for z in (-1.2, 1.2)] + \
             [(x, 5.3, z) for x in (-2.5, 2.5) for z in (-4.0, 4.0)]
    origin = (0.0, 3.0, 0.0)
    g.node("probe_group", translation=origin,
           extras={"kiln": {"probes": [[rnd(c, 6) for c in vsub(p, origin)] for p in probes]}})
    g.node("sun", rotation=look_rotation(AT_SUN),
           light={"name": "sun", "type": "directional", "color": [1.0, 0.95, 0.85],
                  "intensity": 8.0, "extras": {"kiln": {"mode": "baked", "shadowAngle": 0.5}}})
    g.node("camera", translation=(-4.0, 1.7, 0.0),
           rotation=look_rotation(vsub((4.0, 3.0, 1.0), (-4.0, 1.7, 0.0))),
           camera=perspective(math.radians(70.0), 16.0 / 9.0))
    g.write(out_dir, {"kiln": {"sky": {"color": [0.3, 0.4, 0.6]}, "lightmapResolution": 2.0,
                               "bounces": 2}}, "kiln tools/make_scenes.py")
    return g


SCENES = ("cornell_box", "two_rooms", "two_rooms_thin", "courtyard", "atrium")


# ----------------------------------------------------------------------------- --check
COMPONENTS = {5120: ("b", 1), 5121: ("B", 1), 5122: ("h", 2), 5123: ("H", 2), 5125: ("I", 4),
              5126: ("f", 4)}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def quat_matrix(q):
    x, y, z, w = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]


def node_matrix(n):
    """4x4 (rows) local transform of a glTF node."""
    if "matrix" in n:
        m = n["matrix"]
        return [[m[c * 4 + r] for c in range(4)] for r in range(4)]
    r = quat_matrix(n.get("rotation", [0, 0, 0, 1]))
    s = n.get("scale", [1, 1, 1])
    t = n.get("translation", [0, 0, 0])
    return [[r[i][0] * s[0], r[i][1] * s[1], r[i][2] * s[2], t[i]] for i in range(3)] + [[0, 0, 0, 1]]


def mat_mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def mat_point(m, p):
    return tuple(m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3] for i in range(3))


def closest_on_triangle(p, a, b, c):
    """Closest point to p on triangle abc (Ericson, Real-Time Collision Detection 5.1.5)."""
    ab, ac, ap = vsub(b, a), vsub(c, a), vsub(p, a)
    d1, d2 = vdot(ab, ap), vdot(ac, ap)
    if d1 <= 0 and d2 <= 0:
        return a
    bp = vsub(p, b)
    d3, d4 = vdot(ab, bp), vdot(ac, bp)
    if d3 >= 0 and d4 <= d3:
        return b
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        return vadd(a, vmul(ab, d1 / (d1 - d3)))
    cp = vsub(p, c)
    d5, d6 = vdot(ab, cp), vdot(ac, cp)
    if d6 >= 0 and d5 <= d6:
        return c
    vb = d5 * d2 - d1 * d6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        return vadd(a, vmul(ac, d2 / (d2 - d6)))
    va = d3 * d6 - d5 * d4
    if va <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:
        return vadd(b, vmul(vsub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))))
    denom = 1.0 / (va + vb + vc)
    return vadd(a, vadd(vmul(ab, vb * denom), vmul(ac, vc * denom)))


def tri2_overlap(t1, t2, eps=1e-7):
    """Whether two 2D triangles' interiors overlap (separating axis test)."""
    for tri in (t1, t2):
        for i in range(3):
            a, b = tri[i], tri[(i + 1) % 3]
            ax = (b[1] - a[1], a[0] - b[0])
            p1 = [ax[0] * p[0] + ax[1] * p[1] for p in t1]
            p2 = [ax[0] * p[0] + ax[1] * p[1] for p in t2]
            scale = math.hypot(*ax) or 1.0
            if max(p1) <= min(p2) + eps * scale or max(p2) <= min(p1) + eps * scale:
                return False
    return True


def seg_point_dist2(p, a, b):
    ab = (b[0] - a[0], b[1] - a[1])
    ll = ab[0] * ab[0] + ab[1] * ab[1]
    t = 0.0 if ll == 0 else max(0.0, min(1.0, ((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / ll))
    d = (a[0] + ab[0] * t - p[0], a[1] + ab[1] * t - p[1])
    return math.hypot(*d)


def tri2_distance(t1, t2):
    if tri2_overlap(t1, t2, eps=-1e-12):
        return 0.0
    best = float("inf")
    for s, o in ((t1, t2), (t2, t1)):
        for p in s:
            for i in range(3):
                best = min(best, seg_point_dist2(p, o[i], o[(i + 1) % 3]))
    return best


def check_png(path, problems):
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        problems.append("%s: not a PNG" % path)
        return
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        tag, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        if zlib.crc32(tag + body) & 0xFFFFFFFF != crc:
            problems.append("%s: bad CRC in %s" % (path, tag))
        if tag == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat += body
        pos += 12 + length
    w, h, depth, ctype = ihdr[:4]
    if (depth, ctype) != (8, 6) or len(zlib.decompress(idat)) != h * (1 + 4 * w):
        problems.append("%s: not the RGBA8 image its header says" % path)


def check_scene(path):
    """Validates one written scene; returns (problems, summary lines)."""
    problems, notes = [], []
    base = os.path.dirname(path)
    g = json.load(open(path))
    err = problems.append
    if g.get("asset", {}).get("version") != "2.0":
        err("asset.version is not 2.0")
    bufs = []
    for i, b in enumerate(g.get("buffers", [])):
        data = open(os.path.join(base, b["uri"]), "rb").read()
        if len(data) != b["byteLength"]:
            err("buffers[%d]: byteLength %d, file has %d" % (i, b["byteLength"], len(data)))
        bufs.append(data)
    for i, v in enumerate(g.get("bufferViews", [])):
        if v.get("byteOffset", 0) + v["byteLength"] > len(bufs[v["buffer"]]):
            err("bufferViews[%d]: past the end of its buffer" % i)
        if v.get("target") not in (34962, 34963):
            err("bufferViews[%d]: no vertex/index target" % i)

    def read(ai):
        a = g["accessors"][ai]
        v = g["bufferViews"][a["bufferView"]]
        code, size = COMPONENTS[a["componentType"]]
        n = WIDTH[a["type"]]
        stride = v.get("byteStride", size * n)
        off = v.get("byteOffset", 0) + a.get("byteOffset", 0)
        if a.get("byteOffset", 0) % size or off % size:
            err("accessors[%d]: misaligned" % ai)
        if a.get("byteOffset", 0) + stride * (a["count"] - 1) + size * n > v["byteLength"]:
            err("accessors[%d]: does not fit its bufferView" % ai)
            return []
        data = bufs[v["buffer"]]
        return [struct.unpack_from("<%d%s" % (n, code), data, off + k * stride)
                for k in range(a["count"])]

    # Node names and world transforms.
    nodes = g["nodes"]
    names = [n.get("name") for n in nodes]
    if any(not nm for nm in names):
        err("a node has no name")
    if len(set(names)) != len(names):
        err("node names are not unique")
    world = {}

    def walk(i, parent):
        if i in world:
            err("nodes[%d]: reached twice" % i)
            return
        world[i] = mat_mul(parent, node_matrix(nodes[i]))
        for c in nodes[i].get("children", []):
            walk(c, world[i])

    ident = [[1.0 if r == c else 0.0 for c in range(4)] for r in range(4)]
    for r in g["scenes"][g.get("scene", 0)]["nodes"]:
        walk(r, ident)
    if len(world) != len(nodes):
        err("some nodes are not in the scene")

    static_tris = []  # world triangles of static meshes (probe clearance)
    total = 0
    for ni, node in enumerate(nodes):
        if "mesh" not in node:
            continue
        mesh = g["meshes"][node["mesh"]]
        where = "nodes[%d] (%s)" % (ni, node.get("name"))
        uv_tris, area_ratio = [], []
        for pi, prim in enumerate(mesh["primitives"]):
            at = prim["attributes"]
            for key in ("POSITION", "NORMAL", "TEXCOORD_0", "TEXCOORD_1"):
                if key not in at:
                    err("%s: primitive %d has no %s" % (where, pi, key))
            pos, nrm, uv1 = read(at["POSITION"]), read(at["NORMAL"]), read(at["TEXCOORD_1"])
            uv0 = read(at["TEXCOORD_0"])
            if not (len(pos) == len(nrm) == len(uv0) == len(uv1)):
                err("%s: attribute counts differ" % where)
            pa = g["accessors"][at["POSITION"]]
            mn = [min(p[k] for p in pos) for k in range(3)]
            mx = [max(p[k] for p in pos) for k in range(3)]
            if pa.get("min") != mn or pa.get("max") != mx:
                err("%s: POSITION min/max wrong" % where)
            if "material" in prim and prim["material"] >= len(g.get("materials", [])):
                err("%s: bad material index" % where)
            ia = g["accessors"][prim["indices"]]
            if ia["componentType"] not in (5121, 5123, 5125) or ia["count"] % 3:
                err("%s: bad index accessor" % where)
            if g["bufferViews"][ia["bufferView"]].get("target") != 34963:
                err("%s: index bufferView target is not ELEMENT_ARRAY_BUFFER" % where)
            idx = [i[0] for i in read(prim["indices"])]
            if idx and max(idx) >= len(pos):
                err("%s: index %d >= vertex count %d" % (where, max(idx), len(pos)))
                continue
            for n in nrm:
                if abs(vlen(n) - 1.0) > 1e-4:
                    err("%s: normal not unit length" % where)
                    break
            for u in uv1:
                if not all(GUTTER - 1e-5 <= c <= 1.0 - GUTTER + 1e-5 for c in u):
                    err("%s: TEXCOORD_1 %s outside [%g, %g]" % (where, u, GUTTER, 1 - GUTTER))
                    break
            stat = node.get("extras", {}).get("kiln", {}).get("static", True)
            for t in range(0, len(idx), 3):
                a, b, c = idx[t:t + 3]
                geo = vcross(vsub(pos[b], pos[a]), vsub(pos[c], pos[a]))
                area = 0.5 * vlen(geo)
                if area <= 1e-9:
                    err("%s: degenerate triangle" % where)
                    continue
                gn = vnorm(geo)
                if nrm[a] != nrm[b] or nrm[a] != nrm[c] or vdot(gn, nrm[a]) < 0.999:
                    err("%s: triangle %d: normal not flat or against its winding" % (where, t // 3))
                tri = (uv1[a], uv1[b], uv1[c])
                uv_area = 0.5 * abs((tri[1][0] - tri[0][0]) * (tri[2][1] - tri[0][1])
                                    - (tri[2][0] - tri[0][0]) * (tri[1][1] - tri[0][1]))
                area_ratio.append(uv_area / area)
                uv_tris.append(tri)
                if stat:
                    m = world[ni]
                    static_tris.append((mat_point(m, pos[a]), mat_point(m, pos[b]),
                                        mat_point(m, pos[c])))
        total += len(uv_tris)
        # Uniform texel density within the object.
        if area_ratio and max(area_ratio) > min(area_ratio) * 1.01:
            err("%s: lightmap UV area / world area varies (%g..%g)"
                % (where, min(area_ratio), max(area_ratio)))
        # Charts: triangles sharing a UV1 vertex belong to one chart.
        parent = list(range(len(uv_tris)))

        def find(i):
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i

        seen = {}
        for ti, tri in enumerate(uv_tris):
            for p in tri:
                key = (round(p[0], 6), round(p[1], 6))
                if key in seen:
                    parent[find(ti)] = find(seen[key])
                else:
                    seen[key] = ti
        for i in range(len(uv_tris)):
            for j in range(i + 1, len(uv_tris)):
                if find(i) == find(j):
                    if tri2_overlap(uv_tris[i], uv_tris[j]):
                        err("%s: TEXCOORD_1 triangles %d and %d overlap" % (where, i, j))
                elif tri2_distance(uv_tris[i], uv_tris[j]) < GUTTER - 1e-5:
                    err("%s: TEXCOORD_1 charts closer than the %g gutter (triangles %d, %d)"
                        % (where, GUTTER, i, j))
        charts = len({find(i) for i in range(len(uv_tris))})
        used = sum(0.5 * abs((t[1][0] - t[0][0]) * (t[2][1] - t[0][1])
                             - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1])) for t in uv_tris)
        notes.append("  %-18s %4d triangles, %2d charts, UV1 coverage %3.0f%%"
                     % (node["name"], len(uv_tris), charts, 100.0 * used))
    for i, img in enumerate(g.get("images", [])):
        check_png(os.path.join(base, img["uri"]), problems)
    for i, t in enumerate(g.get("textures", [])):
        if t["source"] >= len(g.get("images", [])):
            err("textures[%d]: bad source" % i)
    # Probes: >= 0.3 m from every static surface, on the front side of the nearest one.
    for ni, node in enumerate(nodes):
        probes = node.get("extras", {}).get("kiln", {}).get("probes")
        if probes is None:
            continue
        for p in probes:
            wp = mat_point(world[ni], p)
            near = []
            for a, b, c in static_tris:
                q = closest_on_triangle(wp, a, b, c)
                near.append((vlen(vsub(wp, q)), q, vcross(vsub(b, a), vsub(c, a))))
            dmin = min(n[0] for n in near)
            if dmin < 0.3 - 1e-6:
                err("probe %s (world %s) is %.3f m from a surface" % (p, wp, dmin))
            # At an edge or corner several faces are nearest; one must face the probe.
            elif not any(vdot(vsub(wp, q), n) > 1e-9 for d, q, n in near if d <= dmin + 1e-6):
                err("probe %s (world %s) is behind the nearest surface" % (p, wp))
        notes.append("  %-18s %4d probes" % (node["name"], len(probes)))
    notes.insert(0, "%s: %d triangles" % (os.path.basename(path), total))
    if total > 5000:
        err("more than 5000 triangles")
    return problems, notes


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__ or "Writes kiln's test scenes.")
    ap.add_argument("--out", default=os.path.join(here, "scenes"),
                    help="output directory (default: tools/scenes next to this script)")
    ap.add_argument("--check", action="store_true",
                    help="only validate the scenes already in --out")
    ap.add_argument("--quiet", action="store_true", help="print problems only")
    args = ap.parse_args()
    if not args.check:
        cornell_box(args.out)
        two_rooms(args.out)
        two_rooms(args.out, "two_rooms_thin", TR_THIN)
        courtyard(args.out)
        atrium(args.out)
    failed = False
    for name in SCENES:
        path = os.path.join(args.out, name + ".gltf")
        if not os.path.exists(path):
            print("missing: %s" % path)
            failed = True
            continue
        problems, notes = check_scene(path)
        if not args.quiet:
            print("\n".join(notes))
        for p in problems:
            print("%s: %s" % (name, p))
        failed = failed or bool(problems)
    print("check: FAILED" if failed else "check: ok")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
