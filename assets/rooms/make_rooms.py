#!/usr/bin/env python3
"""Writes bspvt's own test rooms (run from anywhere; rewrites the files next to this script).

- cornell-box.obj + .mtl: the published Cornell box geometry (Cornell University Program of
  Computer Graphics, "Cornell Box Data", in metres), written the way exporters write OBJ: CRLF
  line ends, quads, negative (relative) indices, a 4-vertex floor, materials with Kd and the
  lamp's Ke. Winding: walls face into the box, the blocks face out, the lamp faces down.
- room.gltf: a 4 x 2.5 x 4 m room (glTF 2.0, one embedded buffer): coloured walls, an
  emissive ceiling quad with KHR_materials_emissive_strength, a metal box and a glossy sphere
  under a node hierarchy, and a perspective camera on a node.
- two-lamps.gltf: the same shell lit by two lamps at different heights (issue 34): the ceiling
  lamp and a small pendant lamp 1.2 m lower, facing the floor, off to one side; a board hung at
  1.8 m, between the pendant's height and the ceiling, under the ceiling lamp, shadows the floor
  from it (not from the pendant, which is below it); a box on the floor under the pendant.
- punctual-room.gltf: a shell with a window in its +x wall, lit only by KHR_lights_punctual
  lights, as Blender's glTF exporter writes a scene's lamps: a point light near the ceiling
  over a box, a spot light aimed at a ball, and a sun shining through the window onto the
  floor, where a post stands in its patch (issue 34).
- canopy.gltf: a square lamp 2.5 m above a floor that is one 4 x 4 m quad, and a 1.2 m square
  canopy (a single quad, double-sided) 1 m above the floor: its umbra on the floor is what
  per-vertex shading must not leak light into (issue 35).
- checker-canopy.gltf: the same canopy cut out, as leaves and grilles are modelled: alphaMode
  MASK over an 8 x 8 base-colour texture whose alpha is a checker (half the board open), so
  about half the lamp's light reaches the floor beneath it (issue 35).
- normal-floor.gltf: a 4 x 4 m floor that is one quad, its relief only in a tangent-space normal
  map (normalTexture, scale 1, repeated once a metre: ridges along u, finer ones along v; no
  TANGENT attribute, as exporters often leave it to the client), a 0.4 m box standing on it and
  a square lamp 1.5 m up, off to one side: the ridges facing the lamp are lit, the others dim,
  and the box's shadow falls across them (issue 35).
"""
import base64, json, math, os, struct, zlib

HERE = os.path.dirname(os.path.abspath(__file__))
MM = 0.001

# ---------------------------------------------------------------------------------------------
# Cornell box. Each quad as published (mm); wound below so that the normal faces `inward`.
CENTRE = (278.0, 274.4, 279.6)
WALLS = {
    "floor": [(552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2)],
    "ceiling": [(556, 548.8, 0), (556, 548.8, 559.2), (0, 548.8, 559.2), (0, 548.8, 0)],
    "back": [(549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2), (556, 548.8, 559.2)],
    "green": [(0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2)],
    "red": [(552.8, 0, 0), (549.6, 0, 559.2), (556, 548.8, 559.2), (556, 548.8, 0)],
}
SHORT = [
    [(130, 165, 65), (82, 165, 225), (240, 165, 272), (290, 165, 114)],
    [(290, 0, 114), (290, 165, 114), (240, 165, 272), (240, 0, 272)],
    [(130, 0, 65), (130, 165, 65), (290, 165, 114), (290, 0, 114)],
    [(82, 0, 225), (82, 165, 225), (130, 165, 65), (130, 0, 65)],
    [(240, 0, 272), (240, 165, 272), (82, 165, 225), (82, 0, 225)],
]
TALL = [
    [(423, 330, 247), (265, 330, 296), (314, 330, 456), (472, 330, 406)],
    [(423, 0, 247), (423, 330, 247), (472, 330, 406), (472, 0, 406)],
    [(472, 0, 406), (472, 330, 406), (314, 330, 456), (314, 0, 456)],
    [(314, 0, 456), (314, 330, 456), (265, 330, 296), (265, 0, 296)],
    [(265, 0, 296), (265, 330, 296), (423, 330, 247), (423, 0, 247)],
]
# The lamp, 0.8 mm under the ceiling (the published file puts it in the ceiling's plane).
LAMP = [(343, 548.0, 227), (343, 548.0, 332), (213, 548.0, 332), (213, 548.0, 227)]


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def centroid(q):
    return tuple(sum(c) / len(q) for c in zip(*q))


def facing(quad, toward):
    """The quad wound so that its normal points toward `toward` (a direction)."""
    n = cross(sub(quad[1], quad[0]), sub(quad[2], quad[0]))
    return quad if dot(n, toward) > 0 else list(reversed(quad))


def cornell():
    obj = ["# Cornell box (Cornell University Program of Computer Graphics), metres",
           "# written by assets/rooms/make_rooms.py", "mtllib cornell-box.mtl"]
    def quad(name, mat, q):
        obj.append(f"o {name}")
        obj.append(f"usemtl {mat}")
        for p in q:
            obj.append("v {:.4f} {:.4f} {:.4f}".format(*(c * MM for c in p)))
        obj.append("f -4 -3 -2 -1")
    for name, q in WALLS.items():
        mat = name if name in ("red", "green") else "white"
        quad(name, mat, facing(q, sub(CENTRE, centroid(q))))
    for block, faces in (("short", SHORT), ("tall", TALL)):
        c = centroid([p for f in faces for p in f])
        c = (c[0], 0.0, c[2])
        for i, q in enumerate(faces):
            out = sub(centroid(q), c) if i else (0, 1, 0)
            quad(f"{block}_{i}", "white", facing(q, out))
    quad("light", "light", facing(LAMP, (0, -1, 0)))
    mtl = ["# Cornell box materials (reflectances as in Mitsuba's cornell-box scene)",
           "newmtl white", "Kd 0.725 0.71 0.68", "Ks 0 0 0", "Ns 0",
           "newmtl red", "Kd 0.63 0.065 0.05", "Ks 0 0 0", "Ns 0",
           "newmtl green", "Kd 0.14 0.45 0.091", "Ks 0 0 0", "Ns 0",
           "newmtl light", "Kd 0.78 0.78 0.78", "Ks 0 0 0", "Ns 0", "Ke 17 12 4"]
    with open(os.path.join(HERE, "cornell-box.obj"), "w", newline="") as f:
        f.write("\r\n".join(obj) + "\r\n")
    with open(os.path.join(HERE, "cornell-box.mtl"), "w", newline="") as f:
        f.write("\r\n".join(mtl) + "\r\n")


# ---------------------------------------------------------------------------------------------
# glTF room.
class Gltf:
    def __init__(self):
        self.buf = bytearray()
        self.doc = {"asset": {"version": "2.0", "generator": "bspvt make_rooms.py"},
                    "extensionsUsed": ["KHR_materials_emissive_strength"],
                    "buffers": [], "bufferViews": [], "accessors": [], "meshes": [],
                    "materials": [], "nodes": [], "cameras": [], "scenes": [], "scene": 0}

    def accessor(self, data, fmt, comp, typ, target, minmax=False):
        while len(self.buf) % 4:
            self.buf.append(0)
        off = len(self.buf)
        for row in data:
            self.buf += struct.pack(fmt, *row) if isinstance(row, tuple) else struct.pack(fmt, row)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": off,
                                        "byteLength": len(self.buf) - off, "target": target})
        acc = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": comp,
               "count": len(data), "type": typ}
        if minmax:
            acc["min"] = [min(r[i] for r in data) for i in range(3)]
            acc["max"] = [max(r[i] for r in data) for i in range(3)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def primitive(self, positions, normals, tris, material, uvs=None):
        p = self.accessor(positions, "<3f", 5126, "VEC3", 34962, True)
        n = self.accessor(normals, "<3f", 5126, "VEC3", 34962)
        i = self.accessor([t for tri in tris for t in tri], "<H", 5123, "SCALAR", 34963)
        attributes = {"POSITION": p, "NORMAL": n}
        if uvs:
            attributes["TEXCOORD_0"] = self.accessor(uvs, "<2f", 5126, "VEC2", 34962)
        return {"attributes": attributes, "indices": i, "material": material}

    def png_texture(self, w, h, texel, wrap=33071):
        """An embedded RGBA PNG, `texel(x, y)` its (r, g, b, a) bytes; returns the texture."""
        raw = b"".join(b"\x00" + b"".join(bytes(texel(x, y)) for x in range(w)) for y in range(h))

        def chunk(t, d):
            return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))
        data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
        for k in ("images", "samplers", "textures"):
            self.doc.setdefault(k, [])
        self.doc["images"].append({"uri": "data:image/png;base64," + base64.b64encode(data).decode()})
        self.doc["samplers"].append({"wrapS": wrap, "wrapT": wrap})
        self.doc["textures"].append({"source": len(self.doc["images"]) - 1,
                                     "sampler": len(self.doc["samplers"]) - 1})
        return len(self.doc["textures"]) - 1

    def material(self, name, base, metallic, roughness, emissive=None, strength=None):
        m = {"name": name, "pbrMetallicRoughness": {"baseColorFactor": base + [1.0],
             "metallicFactor": metallic, "roughnessFactor": roughness}}
        if emissive:
            m["emissiveFactor"] = emissive
            m["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}
        self.doc["materials"].append(m)
        return len(self.doc["materials"]) - 1

    def mesh(self, name, prims):
        self.doc["meshes"].append({"name": name, "primitives": prims})
        return len(self.doc["meshes"]) - 1

    def node(self, name, **kw):
        self.doc["nodes"].append({"name": name, **kw})
        return len(self.doc["nodes"]) - 1

    def write(self, path):
        self.doc["buffers"] = [{"byteLength": len(self.buf), "uri":
                                "data:application/octet-stream;base64,"
                                + base64.b64encode(bytes(self.buf)).decode()}]
        with open(path, "w") as f:
            json.dump(self.doc, f, indent=1)
            f.write("\n")


def quad_prim(g, corners, normal, material):
    return g.primitive(corners, [normal] * 4, [(0, 1, 2), (0, 2, 3)], material)


def box(g, half, material):
    prims_p, prims_n, tris = [], [], []
    hx, hy, hz = half
    for axis in range(3):
        for sign in (-1, 1):
            n = [0, 0, 0]
            n[axis] = sign
            u = [0, 0, 0]
            v = [0, 0, 0]
            u[(axis + 1) % 3] = 1
            v[(axis + 2) % 3] = 1
            if sign < 0:
                u, v = v, u
            base = len(prims_p)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [n[i] * half[i] + a * u[i] * half[i] + b * v[i] * half[i] for i in range(3)]
                prims_p.append(tuple(p))
                prims_n.append(tuple(n))
            tris += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return g.primitive(prims_p, prims_n, tris, material)


def sphere(g, r, material, rings=12, segments=24):
    pos, nrm, tris = [], [], []
    for i in range(rings + 1):
        th = math.pi * i / rings
        for j in range(segments + 1):
            ph = 2 * math.pi * j / segments
            n = (math.sin(th) * math.cos(ph), math.cos(th), -math.sin(th) * math.sin(ph))
            pos.append(tuple(r * c for c in n))
            nrm.append(n)
    w = segments + 1
    for i in range(rings):
        for j in range(segments):
            a, b, c, d = i * w + j, i * w + j + 1, (i + 1) * w + j + 1, (i + 1) * w + j
            if i:
                tris.append((a, d, b))
            if i < rings - 1:
                tris.append((b, d, c))
    return g.primitive(pos, nrm, tris, material)


def shell(g, window=None):
    """The 4 x 2.5 x 4 m room; `window` = (y0, y1, z0, z1) cuts an opening in the +x wall."""
    white = g.material("white wall", [0.75, 0.74, 0.72], 0.0, 0.9)
    red = g.material("red wall", [0.7, 0.08, 0.06], 0.0, 0.9)
    blue = g.material("blue wall", [0.1, 0.2, 0.65], 0.0, 0.9)
    floor = g.material("oak floor", [0.55, 0.4, 0.25], 0.0, 0.55)
    X, Y, Z = 2.0, 2.5, 2.0
    return g.mesh("shell", [
        quad_prim(g, [(-X, 0, -Z), (-X, 0, Z), (X, 0, Z), (X, 0, -Z)], (0, 1, 0), floor),
        quad_prim(g, [(-X, Y, -Z), (X, Y, -Z), (X, Y, Z), (-X, Y, Z)], (0, -1, 0), white),
        quad_prim(g, [(-X, 0, -Z), (X, 0, -Z), (X, Y, -Z), (-X, Y, -Z)], (0, 0, 1), white),
        quad_prim(g, [(-X, 0, Z), (-X, Y, Z), (X, Y, Z), (X, 0, Z)], (0, 0, -1), white),
        quad_prim(g, [(-X, 0, -Z), (-X, Y, -Z), (-X, Y, Z), (-X, 0, Z)], (1, 0, 0), red),
    ] + plus_x_wall(g, X, Y, Z, blue, window))


def plus_x_wall(g, X, Y, Z, material, window):
    """The +x wall (facing -x), whole or as four quads around `window`."""
    def part(y0, y1, z0, z1):
        return quad_prim(g, [(X, y0, z0), (X, y0, z1), (X, y1, z1), (X, y1, z0)], (-1, 0, 0),
                         material)
    if window is None:
        return [part(0, Y, -Z, Z)]
    y0, y1, z0, z1 = window
    return [part(0, y0, -Z, Z), part(y1, Y, -Z, Z), part(y0, y1, -Z, z0), part(y0, y1, z1, Z)]


def room():
    g = Gltf()
    shell_mesh = shell(g)
    lamp = g.material("ceiling lamp", [1.0, 1.0, 1.0], 0.0, 1.0, [1.0, 0.9, 0.75], 12.0)
    gold = g.material("brushed gold", [1.0, 0.78, 0.34], 1.0, 0.35)
    glossy = g.material("glossy plastic", [0.05, 0.3, 0.1], 0.0, 0.2)
    Y = 2.5
    s = 0.4  # the lamp: a 0.8 m square 2 cm under the ceiling, in its node's frame
    lamp_mesh = g.mesh("lamp", [quad_prim(g, [(-s, 0, -s), (s, 0, -s), (s, 0, s), (-s, 0, s)],
                                          (0, -1, 0), lamp)])
    box_mesh = g.mesh("metal box", [box(g, (0.35, 0.35, 0.35), gold)])
    ball_mesh = g.mesh("glossy sphere", [sphere(g, 0.4, glossy)])
    g.doc["cameras"].append({"name": "view", "type": "perspective",
                             "perspective": {"yfov": 0.9, "aspectRatio": 1.5,
                                             "znear": 0.05, "zfar": 50.0}})
    # Camera at (0, 1.4, 1.8) looking down its -Z, tilted 12 degrees down.
    t = math.radians(-12) / 2
    nodes = [
        g.node("shell", mesh=shell_mesh),
        g.node("lamp", mesh=lamp_mesh, translation=[0.0, Y - 0.02, 0.0]),
        g.node("furniture", translation=[0.0, 0.0, -0.3], children=[]),
        g.node("camera", camera=0, translation=[0.0, 1.4, 1.8],
               rotation=[math.sin(t), 0.0, 0.0, math.cos(t)]),
    ]
    furniture = g.doc["nodes"][nodes[2]]
    r = math.radians(30) / 2
    furniture["children"] = [
        g.node("metal box", mesh=box_mesh, translation=[-0.7, 0.35, 0.0],
               rotation=[0.0, math.sin(r), 0.0, math.cos(r)]),
        g.node("glossy sphere", mesh=ball_mesh, translation=[0.8, 0.4, 0.3]),
    ]
    g.doc["scenes"].append({"name": "room", "nodes": nodes})
    g.write(os.path.join(HERE, "room.gltf"))


def two_lamps():
    g = Gltf()
    shell_mesh = shell(g)
    ceiling = g.material("ceiling lamp", [1.0, 1.0, 1.0], 0.0, 1.0, [1.0, 0.9, 0.75], 12.0)
    pendant = g.material("pendant lamp", [1.0, 1.0, 1.0], 0.0, 1.0, [0.8, 0.9, 1.0], 40.0)
    board = g.material("painted board", [0.6, 0.6, 0.62], 0.0, 0.6)
    gold = g.material("brushed gold", [1.0, 0.78, 0.34], 1.0, 0.35)
    Y = 2.5

    def down_quad(s, material):
        return quad_prim(g, [(-s, 0, -s), (s, 0, -s), (s, 0, s), (-s, 0, s)], (0, -1, 0),
                         material)

    ceiling_mesh = g.mesh("ceiling lamp", [down_quad(0.4, ceiling)])
    pendant_mesh = g.mesh("pendant lamp", [down_quad(0.15, pendant)])
    # The board: 0.9 x 0.04 x 0.9 m, hung 1.8 m up under the ceiling lamp.
    board_mesh = g.mesh("board", [box(g, (0.45, 0.02, 0.45), board)])
    box_mesh = g.mesh("metal box", [box(g, (0.25, 0.25, 0.25), gold)])
    g.doc["cameras"].append({"name": "view", "type": "perspective",
                             "perspective": {"yfov": 0.9, "aspectRatio": 1.5,
                                             "znear": 0.05, "zfar": 50.0}})
    t = math.radians(-20) / 2
    nodes = [
        g.node("shell", mesh=shell_mesh),
        g.node("ceiling lamp", mesh=ceiling_mesh, translation=[-0.5, Y - 0.02, -0.2]),
        g.node("pendant lamp", mesh=pendant_mesh, translation=[0.9, 1.3, 0.1]),
        g.node("board", mesh=board_mesh, translation=[-0.4, 1.8, -0.2]),
        g.node("metal box", mesh=box_mesh, translation=[0.9, 0.25, -0.2]),
        g.node("camera", camera=0, translation=[0.0, 1.6, 1.9],
               rotation=[math.sin(t), 0.0, 0.0, math.cos(t)]),
    ]
    g.doc["scenes"].append({"name": "two lamps", "nodes": nodes})
    g.write(os.path.join(HERE, "two-lamps.gltf"))


def looking(d):
    """The node rotation (x, y, z, w) that turns -Z toward unit direction `d`."""
    f = (0.0, 0.0, -1.0)
    axis = cross(f, d)
    s = math.sqrt(dot(axis, axis))
    c = dot(f, d)
    if s < 1e-9:
        return [0.0, 0.0, 0.0, 1.0] if c > 0 else [1.0, 0.0, 0.0, 0.0]
    angle = math.atan2(s, c)
    k = math.sin(angle / 2) / s
    return [axis[0] * k, axis[1] * k, axis[2] * k, math.cos(angle / 2)]


def normalized(v):
    n = math.sqrt(dot(v, v))
    return tuple(x / n for x in v)


def punctual_room():
    g = Gltf()
    shell_mesh = shell(g, window=(1.0, 1.8, -0.5, 0.5))
    clay = g.material("clay", [0.7, 0.45, 0.3], 0.0, 0.8)
    glossy = g.material("glossy plastic", [0.05, 0.3, 0.1], 0.0, 0.3)
    box_mesh = g.mesh("box", [box(g, (0.3, 0.3, 0.3), clay)])
    post_mesh = g.mesh("post", [box(g, (0.08, 0.35, 0.08), clay)])
    ball_mesh = g.mesh("ball", [sphere(g, 0.3, glossy)])
    sun_dir = normalized((-0.7, -0.6, 0.15))
    ball = (1.0, 0.3, -1.1)
    spot_at = (0.7, 2.3, -0.3)
    spot_dir = normalized(sub(ball, spot_at))
    g.doc["extensionsUsed"].append("KHR_lights_punctual")
    g.doc["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"name": "bulb", "type": "point", "color": [1.0, 0.85, 0.7], "intensity": 5.0},
        {"name": "spot", "type": "spot", "color": [0.8, 0.9, 1.0], "intensity": 20.0,
         "spot": {"innerConeAngle": math.radians(18), "outerConeAngle": math.radians(26)}},
        {"name": "sun", "type": "directional", "color": [1.0, 0.95, 0.85], "intensity": 4.0},
    ]}}
    g.doc["cameras"].append({"name": "view", "type": "perspective",
                             "perspective": {"yfov": 0.9, "aspectRatio": 1.5,
                                             "znear": 0.05, "zfar": 50.0}})
    t = math.radians(-24) / 2
    nodes = [
        g.node("shell", mesh=shell_mesh),
        g.node("bulb", translation=[-1.0, 2.1, -0.8],
               extensions={"KHR_lights_punctual": {"light": 0}}),
        g.node("spot", translation=list(spot_at), rotation=looking(spot_dir),
               extensions={"KHR_lights_punctual": {"light": 1}}),
        g.node("sun", translation=[3.0, 3.0, 0.0], rotation=looking(sun_dir),
               extensions={"KHR_lights_punctual": {"light": 2}}),
        g.node("box", mesh=box_mesh, translation=[-1.0, 0.3, -0.8]),
        g.node("post", mesh=post_mesh, translation=[0.35, 0.35, 0.2]),
        g.node("ball", mesh=ball_mesh, translation=list(ball)),
        g.node("camera", camera=0, translation=[-0.3, 1.7, 1.9],
               rotation=[math.sin(t), 0.0, 0.0, math.cos(t)]),
    ]
    g.doc["scenes"].append({"name": "punctual room", "nodes": nodes})
    g.write(os.path.join(HERE, "punctual-room.gltf"))


def canopy(checker=False):
    g = Gltf()
    floor = g.material("floor", [0.6, 0.6, 0.6], 0.0, 0.8)
    board = g.material("canopy", [0.5, 0.45, 0.4], 0.0, 0.8)
    g.doc["materials"][board]["doubleSided"] = True
    uvs = None
    if checker:
        # An 8 x 8 checker in alpha (clamped at the edges), cut out at glTF's default 0.5.
        tex = g.png_texture(8, 8, lambda x, y: (200, 180, 150, 255 if (x + y) % 2 == 0 else 0))
        m = g.doc["materials"][board]
        m["name"] = "leaves"
        m["alphaMode"] = "MASK"
        m["pbrMetallicRoughness"]["baseColorTexture"] = {"index": tex}
        uvs = [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)]
    lamp = g.material("lamp", [1.0, 1.0, 1.0], 0.0, 1.0, [1.0, 1.0, 1.0], 10.0)
    F = 2.0
    floor_mesh = g.mesh("floor", [quad_prim(g, [(-F, 0, -F), (-F, 0, F), (F, 0, F), (F, 0, -F)],
                                            (0, 1, 0), floor)])
    c = 0.6
    corners = [(-c, 0, -c), (-c, 0, c), (c, 0, c), (c, 0, -c)]
    canopy_mesh = g.mesh("canopy", [g.primitive(corners, [(0, 1, 0)] * 4, [(0, 1, 2), (0, 2, 3)],
                                                board, uvs)])
    s = 0.25
    lamp_mesh = g.mesh("lamp", [quad_prim(g, [(-s, 0, -s), (s, 0, -s), (s, 0, s), (-s, 0, s)],
                                          (0, -1, 0), lamp)])
    g.doc["cameras"].append({"name": "view", "type": "perspective",
                             "perspective": {"yfov": 0.8, "aspectRatio": 1.5,
                                             "znear": 0.05, "zfar": 50.0}})
    # Low, under the canopy's height, so that the floor beneath it is in view.
    t = math.radians(-16) / 2
    nodes = [
        g.node("floor", mesh=floor_mesh),
        g.node("canopy", mesh=canopy_mesh, translation=[0.0, 1.0, 0.0]),
        g.node("lamp", mesh=lamp_mesh, translation=[0.0, 2.5, 0.0]),
        g.node("camera", camera=0, translation=[0.0, 0.8, 3.0],
               rotation=[math.sin(t), 0.0, 0.0, math.cos(t)]),
    ]
    g.doc["scenes"].append({"name": "checker canopy" if checker else "canopy", "nodes": nodes})
    g.write(os.path.join(HERE, "checker-canopy.gltf" if checker else "canopy.gltf"))


def normal_floor():
    g = Gltf()
    floor = g.material("floor", [0.6, 0.6, 0.6], 0.0, 0.5)
    block = g.material("block", [0.5, 0.45, 0.4], 0.0, 0.8)
    lamp = g.material("lamp", [1.0, 1.0, 1.0], 0.0, 1.0, [1.0, 1.0, 1.0], 10.0)
    # Height h(u, v) = a sin(2 pi u) + b sin(4 pi v) per unit of UV (1 m): the tangent-space
    # normal is (-dh/du, -dh/dy, 1) with y up the image (decreasing v): (-h_u, h_v, 1).
    N, a, b = 64, 0.06, 0.03

    def texel(x, y):
        u, v = (x + 0.5) / N, (y + 0.5) / N
        hu = a * 2 * math.pi * math.cos(2 * math.pi * u)
        hv = b * 4 * math.pi * math.cos(4 * math.pi * v)
        n = normalized((-hu, hv, 1.0))
        return tuple(round((c + 1) * 0.5 * 255) for c in n) + (255,)
    tex = g.png_texture(N, N, texel, wrap=10497)
    g.doc["materials"][floor]["normalTexture"] = {"index": tex, "scale": 1.0}
    F = 2.0
    corners = [(-F, 0, -F), (-F, 0, F), (F, 0, F), (F, 0, -F)]
    uvs = [(c[0] + F, c[2] + F) for c in corners]
    floor_mesh = g.mesh("floor", [g.primitive(corners, [(0, 1, 0)] * 4, [(0, 1, 2), (0, 2, 3)],
                                              floor, uvs)])
    block_mesh = g.mesh("block", [box(g, (0.2, 0.2, 0.2), block)])
    s = 0.25
    lamp_mesh = g.mesh("lamp", [quad_prim(g, [(-s, 0, -s), (s, 0, -s), (s, 0, s), (-s, 0, s)],
                                          (0, -1, 0), lamp)])
    g.doc["cameras"].append({"name": "view", "type": "perspective",
                             "perspective": {"yfov": 0.8, "aspectRatio": 1.5,
                                             "znear": 0.05, "zfar": 50.0}})
    t = math.radians(-30) / 2
    nodes = [
        g.node("floor", mesh=floor_mesh),
        g.node("block", mesh=block_mesh, translation=[-0.3, 0.2, 0.2]),
        g.node("lamp", mesh=lamp_mesh, translation=[0.8, 1.5, -0.3]),
        g.node("camera", camera=0, translation=[0.0, 1.6, 3.0],
               rotation=[math.sin(t), 0.0, 0.0, math.cos(t)]),
    ]
    g.doc["scenes"].append({"name": "normal-mapped floor", "nodes": nodes})
    g.write(os.path.join(HERE, "normal-floor.gltf"))


if __name__ == "__main__":
    cornell()
    room()
    two_lamps()
    punctual_room()
    canopy()
    canopy(checker=True)
    normal_floor()
