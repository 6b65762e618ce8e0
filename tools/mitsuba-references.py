#!/usr/bin/env python3
"""Renders the Mitsuba 3 references of zerovar's validation scenes (tests/data/mitsuba/*.xml).

Requires Mitsuba 3 from PyPI (this script installs nothing):

    pip install mitsuba

and runs its `scalar_rgb` variant, which needs no GPU and no LLVM. For every scene it renders K
independent images (sampler seeds 0..K-1) of `SPP` samples per pixel each and writes
tests/data/mitsuba/<scene>.exr in the layout of `zerovar reference`: the mean RGB as channels
R, G, B and the per-pixel standard error of that mean (the standard deviation of the K images
over sqrt(K)) as channels stderr.R, stderr.G, stderr.B, 32-bit float. tests/mitsuba.rs renders
each scene with zerovar and compares the two per pixel by z-scores.

Usage: python3 tools/mitsuba-references.py [scene.xml ...]   (default: every validation scene)

ZEROVAR_REF_RUNS and ZEROVAR_REF_SPP override K and SPP (for a quicker reference: K of at least
16 keeps the standard error's own error near 18%, which the z statistics tolerate).
"""

import glob
import os
import sys
import time

import numpy as np
import mitsuba as mi

VARIANT = "scalar_rgb"
# K independent renders: the standard error's own error is about 1/sqrt(2(K-1)) = 13%
RUNS = int(os.environ.get("ZEROVAR_REF_RUNS", 32))
SPP = int(os.environ.get("ZEROVAR_REF_SPP", 1024))  # samples per pixel of each render
if RUNS < 16 or SPP < 1:
    sys.exit("ZEROVAR_REF_RUNS must be at least 16 and ZEROVAR_REF_SPP at least 1")

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "tests", "data", "mitsuba")


def reference(path):
    scene = mi.load_file(path, spp=SPP)
    total = None
    total_sq = None
    for seed in range(RUNS):
        img = np.array(mi.render(scene, spp=SPP, seed=seed), dtype=np.float64)[:, :, :3]
        total = img if total is None else total + img
        total_sq = img * img if total_sq is None else total_sq + img * img
    mean = total / RUNS
    var = np.maximum(total_sq / RUNS - mean * mean, 0.0) * RUNS / (RUNS - 1)
    stderr = np.sqrt(var / RUNS)
    data = np.concatenate([mean, stderr], axis=2).astype(np.float32)
    out = os.path.splitext(path)[0] + ".exr"
    bitmap = mi.Bitmap(
        data,
        pixel_format=mi.Bitmap.PixelFormat.MultiChannel,
        channel_names=["R", "G", "B", "stderr.R", "stderr.G", "stderr.B"],
    )
    bitmap.write(out)
    return out, mean, stderr


def main():
    mi.set_variant(VARIANT)
    print(f"Mitsuba {mi.__version__}, variant {VARIANT}: {RUNS} runs x {SPP} spp per scene")
    scenes = sys.argv[1:] or sorted(glob.glob(os.path.join(DATA, "*.xml")))
    for path in scenes:
        start = time.time()
        out, mean, stderr = reference(path)
        rel = np.median(stderr / np.maximum(mean, 1e-6))
        print(
            f"{os.path.relpath(out)}: mean {mean.mean(axis=(0, 1)).round(4)}, "
            f"median relative stderr {rel:.4f}, {time.time() - start:.1f} s"
        )


if __name__ == "__main__":
    main()
