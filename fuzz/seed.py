#!/usr/bin/env python3
"""Writes the fuzz targets' seed corpora into fuzz/corpus/<target>/: the project's rooms and
scenes, the shared meshes under 256 KiB (../shared/assets/meshes, or $BSPVT_MESHES), GLB and
binary PLY versions made here, multipart submissions built from them, and a real bake when a
bspvt-server binary is given (argument 1). Seeds are valid inputs; the fuzzer mutates them."""
import base64, glob, json, os, re, shutil, struct, subprocess, sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
MESHES = os.environ.get("BSPVT_MESHES", os.path.join(ROOT, "..", "shared", "assets", "meshes"))
CORPUS = os.path.join(HERE, "corpus")
MAX_SEED = 256 << 10
BOUNDARY = "bspvt-fuzz"  # server/src/service/fuzz.rs, BOUNDARY


def put(target, name, data):
    d = os.path.join(CORPUS, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())


def read(path):
    with open(path, "rb") as f:
        return f.read()


def glb(gltf_text):
    """A .gltf whose single buffer is a data URI, as a binary glTF (the buffer in its BIN chunk)."""
    j = json.loads(gltf_text)
    if len(j.get("buffers", [])) != 1:
        return None
    uri = j["buffers"][0].pop("uri", "")
    if not uri.startswith("data:"):
        return None
    data = base64.b64decode(uri.split(",", 1)[1])
    js = json.dumps(j, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    data += b"\0" * (-len(data) % 4)
    total = 12 + 8 + len(js) + 8 + len(data)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(js)) + b"JSON" + js
            + struct.pack("<I", len(data)) + b"BIN\0" + data)


def ply_binary(big_endian):
    """A tetrahedron with normals, binary PLY."""
    e = ">" if big_endian else "<"
    fmt = "binary_big_endian" if big_endian else "binary_little_endian"
    out = (f"ply\nformat {fmt} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
           "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
           "element face 4\nproperty list uchar int vertex_indices\nend_header\n").encode()
    for p in [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        out += struct.pack(e + "6f", *p, 0, 1, 0)
    for f in [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]:
        out += struct.pack(e + "B3i", 3, *f)
    return out


def multipart(fields):
    """fields: (name, file name or None, bytes)."""
    out = b""
    for name, file_name, data in fields:
        disp = f'form-data; name="{name}"' + (f'; filename="{file_name}"' if file_name else "")
        out += f"--{BOUNDARY}\r\nContent-Disposition: {disp}\r\n\r\n".encode() + data + b"\r\n"
    return out + f"--{BOUNDARY}--\r\n".encode()


def main():
    shutil.rmtree(CORPUS, ignore_errors=True)
    rooms = os.path.join(ROOT, "assets", "rooms")
    small_obj = b"v 0 0 0\nv 1 0 0\nv 0 0 1\nv 1 0.5 1\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 1 0\n" \
                b"mtllib m.mtl\nusemtl a\nf 1/1/1 3/3/1 2/2/1\nf -3 -2 -1\n"
    # Meshes.
    for path in sorted(glob.glob(os.path.join(rooms, "*.gltf"))):
        name = os.path.basename(path)
        text = read(path)
        put("gltf", name, text)
        b = glb(text)
        if b:
            put("glb", name[:-5] + ".glb", b)
    put("obj", "cornell-box.obj", read(os.path.join(rooms, "cornell-box.obj")))
    put("obj", "small.obj", small_obj)
    put("ply", "tetra-le.ply", ply_binary(False))
    put("ply", "tetra-be.ply", ply_binary(True))
    shared = 0
    for path in sorted(glob.glob(os.path.join(MESHES, "*"))):
        ext = os.path.splitext(path)[1][1:]
        if ext in ("obj", "ply") and os.path.getsize(path) <= MAX_SEED:
            put(ext, os.path.basename(path), read(path))
            shared += 1
    if shared == 0:
        print(f"seed.py: no shared meshes under {MESHES}; seeding from the project's files only")
    # Scenes: the project's, each also naming the uploaded mesh.obj.
    for path in sorted(glob.glob(os.path.join(ROOT, "assets", "scenes", "*.json"))):
        text = read(path).decode()
        name = os.path.basename(path)
        put("scene_json", name, text)
        put("scene_json", "upload-" + name, re.sub(r'"path":\s*"[^"]*"', '"path": "mesh.obj"', text))
    # Submissions.
    plate = read(os.path.join(ROOT, "assets", "scenes", "plate.json"))
    # A `settings` field without `refine` skips the refinement of large flat polygons (seconds
    # per room: too slow to fuzz), so these explore the form, the importers and composition.
    settings = b'{"face_res": 16, "epsilon": 0.001, "supersampling": 1, "split": "default", "chunk_vertices": 64}'
    put("upload", "obj-mtl", multipart([
        ("mesh", "cornell-box.obj", read(os.path.join(rooms, "cornell-box.obj"))),
        ("file", "cornell-box.mtl", read(os.path.join(rooms, "cornell-box.mtl"))),
        ("settings", None, settings)]))
    for room in ("canopy", "textured-floor", "normal-floor", "punctual-room"):
        put("upload", room, multipart([
            ("mesh", room + ".gltf", read(os.path.join(rooms, room + ".gltf"))),
            ("settings", None, settings)]))
    put("upload", "obj-bare", multipart([("mesh", "small.obj", small_obj),
                                         ("file", "m.mtl", b"newmtl a\nKd 0.5 0.4 0.3\n")]))
    put("upload", "scene", multipart([("scene", None, plate)]))
    put("upload", "scene-mesh-settings", multipart([
        ("mesh", "mesh.obj", small_obj),
        ("file", "m.mtl", b"newmtl a\nKd 0.5 0.4 0.3\nNs 100\n"),
        ("scene", None, re.sub(rb'"path":\s*"[^"]*"', b'"path": "mesh.obj"', plate)),
        ("settings", None, settings)]))
    put("upload", "ply", multipart([("mesh", "tetra.ply", ply_binary(False))]))
    # A real bake.
    if len(sys.argv) > 1:
        out = os.path.join(CORPUS, "bake", "plate-small.bspvt")
        os.makedirs(os.path.dirname(out), exist_ok=True)
        subprocess.run([sys.argv[1], "bake", "builtin:plate-small", "--face-res", "8",
                        "--out", out], check=True, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL)
        # Each frame alone too (the header, each chunk, the mesh): the chunk decoder's seeds.
        data = read(out)
        pos, k = 0, 0
        while pos < len(data):
            m = 6 if data[pos:pos + 6] == b"BSPVT\0" else 4
            (n,) = struct.unpack_from("<I", data, pos + m)
            end = pos + m + 4 + n + 4
            put("bake", f"frame-{k}-{data[pos:pos + 4].decode(errors='replace')}", data[pos:end])
            pos, k = end, k + 1
    else:
        print("seed.py: no bspvt-server given; the bake target starts from an empty corpus")
    for t in sorted(os.listdir(CORPUS)):
        files = os.listdir(os.path.join(CORPUS, t))
        print(f"seed.py: {t}: {len(files)} seeds")


if __name__ == "__main__":
    main()
