#!/usr/bin/env python3
"""Midpoint subdivision of a PLY mesh (each triangle into four), written as binary PLY.

Makes the large meshes of the GPU bake benchmark (issue 23: a ~500K-vertex bake) from the
shared Stanford bunny on the device machine, where nothing can be fetched:

    python3 tools/device/subdivide.py IN.ply OUT.ply LEVELS
"""
import struct
import sys

import numpy as np


def read_ply(path):
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline().decode("ascii").strip()
            header.append(line)
            if line == "end_header":
                break
        fmt = next(l.split()[1] for l in header if l.startswith("format"))
        nv = nf = 0
        props = []
        element = None
        for l in header:
            w = l.split()
            if w[:2] == ["element", "vertex"]:
                nv, element = int(w[2]), "vertex"
            elif w[:2] == ["element", "face"]:
                nf, element = int(w[2]), "face"
            elif w[0] == "property" and element == "vertex":
                props.append(w[-1])
        if fmt != "ascii":
            raise SystemExit(f"{path}: only ASCII PLY input is supported here")
        text = f.read().split()
    k = len(props)
    vals = np.array(text[: nv * k], dtype=np.float64).reshape(nv, k)
    xyz = vals[:, [props.index("x"), props.index("y"), props.index("z")]]
    rest = text[nv * k :]
    faces = []
    i = 0
    for _ in range(nf):
        n = int(rest[i])
        idx = [int(x) for x in rest[i + 1 : i + 1 + n]]
        for j in range(1, n - 1):
            faces.append((idx[0], idx[j], idx[j + 1]))
        i += 1 + n
    return xyz, np.array(faces, dtype=np.int64)


def subdivide(v, f):
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.sort(edges, axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    mids = 0.5 * (v[uniq[:, 0]] + v[uniq[:, 1]])
    base = len(v)
    m = inv.reshape(3, -1).T + base  # midpoints of edges 01, 12, 20 per face
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    m01, m12, m20 = m[:, 0], m[:, 1], m[:, 2]
    nf = np.concatenate(
        [
            np.stack([a, m01, m20], 1),
            np.stack([m01, b, m12], 1),
            np.stack([m20, m12, c], 1),
            np.stack([m01, m12, m20], 1),
        ]
    )
    return np.concatenate([v, mids]), nf


def write_ply(path, v, f):
    with open(path, "wb") as out:
        out.write(
            (
                "ply\nformat binary_little_endian 1.0\n"
                f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
                f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
            ).encode("ascii")
        )
        out.write(v.astype("<f4").tobytes())
        rec = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
        rec["n"] = 3
        rec["i"] = f
        out.write(rec.tobytes())


if __name__ == "__main__":
    src, dst, levels = sys.argv[1], sys.argv[2], int(sys.argv[3])
    v, f = read_ply(src)
    for _ in range(levels):
        v, f = subdivide(v, f)
    write_ply(dst, v, f)
    print(f"{dst}: {len(v)} vertices, {len(f)} triangles")
