#!/usr/bin/env python3
"""GPU against CPU frames of one scene, over the whole image and where the shadows are.

Usage: shadow_diff.py CPU.png GPU.png UNSHADOWED.png
The shadowed pixels are those the CPU frame draws below 80 % of the unshadowed LTC frame's
luminance (umbrae and penumbrae). Prints the share of shadowed pixels and the mean |GPU − CPU|
luminance (linear, from the 8-bit sRGB PNGs) relative to the CPU's mean, whole and shadowed.
Needs numpy and pillow.
"""
import sys

import numpy as np
from PIL import Image


def luminance(path):
    a = np.asarray(Image.open(path).convert("RGB")).astype(np.float64) / 255
    a = np.where(a <= 0.04045, a / 12.92, ((a + 0.055) / 1.055) ** 2.4)
    return a @ [0.2126, 0.7152, 0.0722]


cpu, gpu, unshadowed = (luminance(p) for p in sys.argv[1:4])
shadow = (cpu < 0.8 * unshadowed) & (unshadowed > 0.01)
d = np.abs(gpu - cpu)
whole = d.mean() / max(cpu.mean(), 1e-12)
inside = d[shadow].mean() / max(cpu[shadow].mean(), 1e-12) if shadow.any() else 0.0
print(f"shadowed pixels {shadow.mean() * 100:.1f} %; mean |GPU - CPU| / mean: "
      f"whole {whole * 100:.2f} %, in shadows {inside * 100:.2f} %")
