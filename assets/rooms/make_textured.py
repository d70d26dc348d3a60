#!/usr/bin/env python3
"""Writes textured-floor.gltf next to this script: bspvt's own small textured asset (glTF 2.0,
everything embedded as data: URIs).

- a 2 m floor (y = 0, an N x N grid, N = 1 by default) with a 16 x 16 sRGB checker base-colour
  texture of 8 x 8 blocks (red, green / blue, white; clamp-to-edge), u = (x + 1) / 2, v = (z + 1) / 2;
- a 0.5 m emissive lamp at y = 2 facing down (emissiveStrength 8) whose emissive texture is
  2 x 1 (black, white): the lamp's x < 0 half is dark;
- a KHR_lights_punctual spot (20 cd, outer cone 0.6 rad) at (0.5, 1, 0) pointing down its
  node's -Z, turned 60 degrees down from -Z (it lights the floor obliquely, toward -z).

`make_textured.py --plain OUT` writes the same asset without textures (the measurement's
baseline); `--grid N` sets N.
"""
import argparse, base64, json, os, struct, sys, zlib

ap = argparse.ArgumentParser()
ap.add_argument('--plain')
ap.add_argument('--grid', type=int, default=1)
args = ap.parse_args()
def png(w,h,px):
    raw=b''.join(b'\x00'+b''.join(bytes(px(x,y)) for x in range(w)) for y in range(h))
    def chunk(t,d): return struct.pack('>I',len(d))+t+d+struct.pack('>I',zlib.crc32(t+d)&0xffffffff)
    return b'\x89PNG\r\n\x1a\n'+chunk(b'IHDR',struct.pack('>IIBBBBB',w,h,8,6,0,0,0))+chunk(b'IDAT',zlib.compress(raw))+chunk(b'IEND',b'')
checker=png(16,16,lambda x,y:[(255,0,0,255),(0,255,0,255),(0,0,255,255),(255,255,255,255)][(y//8)*2+x//8])
half=png(2,1,lambda x,y:(0,0,0,255) if x==0 else (255,255,255,255))
def f32(v): return b''.join(struct.pack('<f',x) for x in v)
bin=b''; views=[]; accs=[]
def push(data,acc):
    global bin
    while len(bin)%4: bin+=b'\0'
    views.append({"buffer":0,"byteOffset":len(bin),"byteLength":len(data)}); bin+=data
    acc["bufferView"]=len(views)-1; accs.append(acc); return len(accs)-1
prims=[]
n=args.grid   # floor grid cells per side
# floor grid n x n cells
P=[];UV=[];I=[]
for j in range(n+1):
  for i in range(n+1):
    x=-1+2*i/n; z=-1+2*j/n; P.append((x,0,z)); UV.append(((x+1)/2,(z+1)/2))
for j in range(n):
  for i in range(n):
    a=j*(n+1)+i; b=a+1; c=a+n+1; d=c+1
    I+= [a,c,d,a,d,b]
floor=(P,(0,1,0),UV,I,0)
lampP=[(-0.25,2,-0.25),(0.25,2,-0.25),(0.25,2,0.25),(-0.25,2,0.25)]
lamp=(lampP,(0,-1,0),[(0,0),(1,0),(1,1),(0,1)],[0,1,2,0,2,3],1)
meshes=[]
for (P,N,UV,I,m) in [floor,lamp]:
    lo=[min(p[k] for p in P) for k in range(3)]; hi=[max(p[k] for p in P) for k in range(3)]
    pa=push(f32([c for p in P for c in p]),{"componentType":5126,"count":len(P),"type":"VEC3","min":lo,"max":hi})
    na=push(f32(list(N)*len(P)),{"componentType":5126,"count":len(P),"type":"VEC3"})
    ua=push(f32([c for p in UV for c in p]),{"componentType":5126,"count":len(P),"type":"VEC2"})
    ia=push(b''.join(struct.pack('<I',i) for i in I),{"componentType":5125,"count":len(I),"type":"SCALAR"})
    meshes.append({"primitives":[{"attributes":{"POSITION":pa,"NORMAL":na,"TEXCOORD_0":ua},"indices":ia,"material":m}]})
doc={"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0,1,2]}],
 "nodes":[{"mesh":0},{"mesh":1},{"translation":[0.5,1.0,0.0],"rotation":[-0.5,0.0,0.0,0.8660254],"extensions":{"KHR_lights_punctual":{"light":0}}}],
 "meshes":meshes,
 "extensionsUsed":["KHR_materials_emissive_strength","KHR_lights_punctual"],
 "extensions":{"KHR_lights_punctual":{"lights":[{"type":"spot","intensity":20,"spot":{"outerConeAngle":0.6}}]}},
 "materials":[{"name":"floor","pbrMetallicRoughness":{"baseColorTexture":{"index":0},"metallicFactor":0.0,"roughnessFactor":0.6}},
  {"name":"lamp","emissiveFactor":[1,1,1],"emissiveTexture":{"index":1},"extensions":{"KHR_materials_emissive_strength":{"emissiveStrength":8}}}],
 "samplers":[{"wrapS":33071,"wrapT":33071}],
 "textures":[{"source":0,"sampler":0},{"source":1,"sampler":0}],
 "images":[{"uri":"data:image/png;base64,"+base64.b64encode(checker).decode()},{"uri":"data:image/png;base64,"+base64.b64encode(half).decode()}],
 "accessors":accs,"bufferViews":views,
 "buffers":[{"byteLength":len(bin),"uri":"data:application/octet-stream;base64,"+base64.b64encode(bin).decode()}]}
if args.plain:
    for k in ("textures","images","samplers"):
        doc.pop(k)
    doc["materials"][0]["pbrMetallicRoughness"].pop("baseColorTexture")
    doc["materials"][1].pop("emissiveTexture")
out = args.plain or os.path.join(os.path.dirname(os.path.abspath(__file__)), "textured-floor.gltf")
with open(out, "w") as f:
    f.write(json.dumps(doc, indent=1) + "\n")
