#!/usr/bin/env python3
"""Agreement with Mitsuba 3's own participating-media test suite (tests/scenes/
participating_media in mitsuba-renderer/mitsuba-data, 12 scenes with RGB references).

Per scene and guiding mode: 4 renders with seeds 1..4 at an spp chosen so that each takes
about --seconds; per 4x4 block and channel, a t-test (3 degrees of freedom) of their mean
against the reference's block (whose own noise is not counted, which makes the test the
stricter); prints the share of blocks at p < 1e-3 and the image mean over the reference's.

Usage: python3 tools/mitsuba-suite.py ZEROVAR SUITE_DIR [--modes off,full] [--seconds 4]
(SUITE_DIR holds the test_*.xml files and refs/; needs numpy and OpenEXR)
"""

import argparse
import glob
import math
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "bench"))
import unbiased  # noqa: E402  (load, t_two_sided)

BLOCK = 4


def blocks(img):
    h, w, _ = img.shape
    return img[: h // BLOCK * BLOCK, : w // BLOCK * BLOCK].reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, 3).mean(axis=(1, 3))


def render(zerovar, scene, mode, spp, seed, out):
    cmd = [zerovar, "render", scene, "--guiding", mode, "--spp", str(spp), "--seed", str(seed), "-o", out, "--quiet"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return unbiased.load(out)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("zerovar")
    p.add_argument("suite")
    p.add_argument("--modes", default="off,full")
    p.add_argument("--seconds", type=float, default=4.0)
    a = p.parse_args()
    zerovar = os.path.abspath(a.zerovar)
    os.chdir(a.suite)
    out = "/tmp/zerovar-mitsuba-suite.exr"
    print("| scene | mode | spp x seeds | blocks at p < 1e-3 | image mean / reference |")
    print("|---|---|---|---|---|")
    for scene in sorted(glob.glob("test_*.xml")):
        name = scene.rsplit("_volpath", 1)[0]
        ref = blocks(unbiased.load(f"refs/{name}_ref_rgb.exr"))
        start = time.time()
        render(zerovar, scene, "off", 16, 0, out)
        per_spp = max(time.time() - start, 0.02) / 16
        spp = int(min(4096, max(64, 2 ** round(math.log2(a.seconds / per_spp)))))
        for mode in a.modes.split(","):
            runs = np.array([blocks(render(zerovar, scene, mode, spp, s, out)) for s in range(1, 5)])
            mean, se = runs.mean(0), runs.std(0, ddof=1) / 2
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(se > 0, (mean - ref) / se, np.where(mean == ref, 0.0, np.inf))
            rejected = unbiased.t_two_sided(t, 3) < 1e-3
            ratio = runs.mean() / ref.mean()
            print(f"| {name} | {mode} | {spp} x 4 | {rejected.sum()} of {rejected.size} ({100 * rejected.mean():.1f}%) | {ratio:.4f} |", flush=True)


if __name__ == "__main__":
    main()
