#!/usr/bin/env python3
"""Mitsuba 3 side of bspvt's ground-truth cross-check (docs/groundtruth.md).

render: renders a scene written by `bspvt export-mitsuba` in PASSES independent passes (seeds
        SEED*1000 + k) of SPP samples each, and writes OUT/mitsuba_mean.exr (mean of the passes)
        and OUT/mitsuba_stderr.exr (standard error of that mean, from the passes' spread).
check-bsdf: evaluates the BSDFs the exporter writes (blendbsdf of diffuse and principled with
        metallic = 1, or roughconductor with material = none) at random direction pairs and
        compares them with bspvt's BRDF, albedo/pi + F D G1 G1 / (4 cos cos) with Schlick F,
        written out here independently. Prints the largest relative error.

Needs `pip install mitsuba` (variant scalar_rgb; numpy is not needed).
"""

import argparse
import math
import os
import random
import sys
import time

import mitsuba as mi


def render(args):
    mi.set_variant(args.variant)
    import drjit as dr

    scene = mi.load_file(args.scene)
    s1 = None
    s2 = None
    t0 = time.time()
    for k in range(args.passes):
        img = mi.render(scene, spp=args.spp, seed=args.seed * 1000 + k)
        if s1 is None:
            s1, s2 = img, img * img
        else:
            s1, s2 = s1 + img, s2 + img * img
    n = float(args.passes)
    mean = s1 / n
    var = dr.maximum((s2 / n - mean * mean) * (n / max(n - 1.0, 1.0)), 0.0)
    se = dr.sqrt(var / n)
    os.makedirs(args.out, exist_ok=True)
    mi.Bitmap(mean).write(os.path.join(args.out, "mitsuba_mean.exr"))
    mi.Bitmap(se).write(os.path.join(args.out, "mitsuba_stderr.exr"))
    print(
        f"mitsuba {mi.__version__} {args.variant}: {args.passes} x {args.spp} spp "
        f"in {time.time() - t0:.1f} s -> {args.out}"
    )


# --- BSDF check -------------------------------------------------------------------------

def ggx_d(a, cos_h):
    if cos_h <= 0:
        return 0.0
    a2 = a * a
    c2 = cos_h * cos_h
    k = a2 * c2 + (1 - c2)
    return a2 / (math.pi * k * k)


def smith_g1(a, cos_t):
    if cos_t <= 0:
        return 0.0
    t2 = (1 - cos_t * cos_t) / (cos_t * cos_t)
    return 2.0 / (1.0 + math.sqrt(1.0 + a * a * t2))


def ours(albedo, f0, a, wo, wi):
    """f(wo, wi) cos(theta_i), per channel."""
    if wo[2] <= 0 or wi[2] <= 0:
        return [0.0, 0.0, 0.0]
    h = [wo[i] + wi[i] for i in range(3)]
    ln = math.sqrt(sum(x * x for x in h))
    h = [x / ln for x in h]
    cos_d = sum(wi[i] * h[i] for i in range(3))
    s = max(0.0, min(1.0, 1 - cos_d)) ** 5
    spec = ggx_d(a, h[2]) * smith_g1(a, wo[2]) * smith_g1(a, wi[2]) / (4 * wo[2])
    return [albedo[c] / math.pi * wi[2] + (f0[c] + (1 - f0[c]) * s) * spec for c in range(3)]


def rand_dir(rng, min_z):
    z = rng.uniform(min_z, 1.0)
    r = math.sqrt(1 - z * z)
    p = rng.uniform(0, 2 * math.pi)
    return [r * math.cos(p), r * math.sin(p), z]


def check_bsdf(args):
    mi.set_variant(args.variant)
    rng = random.Random(1)
    worst = 0.0
    cases = [
        ([0.55, 0.55, 0.52], [0.04, 0.04, 0.04], 0.35),
        ([0.6, 0.15, 0.1], [0.05, 0.05, 0.05], 0.15),
        ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], 0.3),
        ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], 0.05),
        ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], 2e-3),
        ([0.3, 0.2, 0.1], [0.9, 0.5, 0.1], 0.7),
        ([0.5, 0.5, 0.5], [0.0, 0.0, 0.0], 1.0),
    ]
    for albedo, f0, a in cases:
        if all(c >= 1.0 for c in f0):
            spec = {"type": "roughconductor", "material": "none", "distribution": "ggx",
                    "alpha": a, "sample_visible": True}
        else:
            spec = {"type": "principled", "base_color": {"type": "rgb", "value": f0},
                    "metallic": 1.0, "roughness": math.sqrt(a)}
        bsdf = mi.load_dict({"type": "blendbsdf", "weight": 0.5,
                             "a": {"type": "diffuse",
                                   "reflectance": {"type": "rgb", "value": albedo}},
                             "b": spec})
        ctx = mi.BSDFContext()
        for _ in range(400):
            wo = rand_dir(rng, 0.02)  # our view direction = Mitsuba's si.wi
            # Half the pairs near the mirror direction, where the specular lobe lives.
            if rng.random() < 0.5:
                wi = rand_dir(rng, 0.02)
            else:
                m = [-wo[0], -wo[1], wo[2]]
                wi = [m[i] + rng.gauss(0, max(a, 0.01)) for i in range(3)]
                ln = math.sqrt(sum(x * x for x in wi))
                wi = [x / ln for x in wi]
                if wi[2] <= 0.02:
                    continue
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(wo)
            si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            got = bsdf.eval(ctx, si, mi.Vector3f(wi))
            got = [2.0 * float(got[c]) for c in range(3)]  # x2: the doubled emitter
            want = ours(albedo, f0, a, wo, wi)
            for c in range(3):
                err = abs(got[c] - want[c]) / max(abs(want[c]), 1e-3)
                worst = max(worst, err)
    print(f"bsdf check: max relative error {worst:.2e}")
    if worst > args.tolerance:
        sys.exit(f"bsdf check failed: {worst:.2e} > {args.tolerance:.1e}")


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variant", default="scalar_rgb")
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render")
    r.add_argument("scene")
    r.add_argument("--out", required=True)
    r.add_argument("--spp", type=int, default=256, help="samples per pixel per pass")
    r.add_argument("--passes", type=int, default=16)
    r.add_argument("--seed", type=int, default=0)
    c = sub.add_parser("check-bsdf")
    c.add_argument("--tolerance", type=float, default=1e-3)
    args = ap.parse_args()
    if args.cmd == "render":
        render(args)
    else:
        check_bsdf(args)


if __name__ == "__main__":
    main()
