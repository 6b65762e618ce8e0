#!/usr/bin/env python3
"""Fits the per-operation costs of `--guiding auto`'s cost model (src/render/select.rs).

Renders every example and bench scene unguided, fully guided and with each guided component
alone, single-threaded at a few spp with `--stats`, and fits the render seconds as a
non-negative combination of the counted operations, minimising the relative error (so cheap
scenes weigh as much as expensive ones). Prints the constants and, per scene, the measured
and predicted cost of a fully guided sample over an unguided one.

Usage: tools/fit-cost-model.py [SPP] [TRAIN_PASSES]   (defaults 8 and 4)
Timings need a quiet machine: run nothing else meanwhile.
"""

import glob
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(ROOT, "target", "release", "zerovar")
MODES = ["off", "full", "directions", "distances", "rr"]
# (constant in select.rs, counters per path in the stats, which are multiplied by paths)
TERMS = [
    ("NS_PER_PATH", None),
    ("NS_PER_SEGMENT", "mean_path_length"),
    ("NS_PER_SCATTER", "scatter_events_per_path"),
    ("NS_PER_DENSITY_LOOKUP", "unguided_density_lookups_per_path"),
    ("NS_PER_GUIDED_DENSITY_LOOKUP", "guided_density_lookups_per_path"),
    ("NS_PER_FIELD_LOOKUP", "field_lookups_per_path"),
    ("NS_PER_PRODUCT", "products_per_path"),
    ("NS_PER_LOBE_PRODUCT", "lobe_products_per_path"),
    ("NS_PER_EXTRA_COLLISION", "extra_collisions_per_path"),
]


def render(scene, mode, spp, passes, out):
    stats = os.path.join(out, "stats.json")
    cmd = [BIN, "render", scene, "--guiding", mode, "--spp", str(spp), "--threads", "1",
           "--train-passes", str(passes), "--stats", stats, "--quiet",
           "-o", os.path.join(out, "image.exr")]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(stats) as f:
        s = json.load(f)
    s["unguided_density_lookups_per_path"] = (
        s["density_lookups_per_path"] - s["guided_density_lookups_per_path"])
    return s


def nnls(a, b, iterations=20000):
    """Non-negative least squares by projected coordinate descent (a few unknowns)."""
    x = np.zeros(a.shape[1])
    ata, atb = a.T @ a, a.T @ b
    for _ in range(iterations):
        before = x.copy()
        for j in range(len(x)):
            if ata[j, j] > 0:
                x[j] = max(0.0, x[j] + (atb[j] - ata[j] @ x) / ata[j, j])
        if np.max(np.abs(x - before)) < 1e-9 * max(1.0, np.max(np.abs(x))):
            break
    return x


def main():
    spp = int(sys.argv[1]) if len(sys.argv) > 1 else 8
    passes = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    scenes = sorted(glob.glob(os.path.join(ROOT, "scenes", "*.toml"))
                    + glob.glob(os.path.join(ROOT, "scenes", "bench", "*.toml")))
    rows = []
    with tempfile.TemporaryDirectory() as out:
        for scene in scenes:
            for mode in MODES:
                s = render(scene, mode, spp, passes, out)
                paths = s["paths_per_second"] * s["seconds"]
                counts = [paths] + [paths * s[k] for _, k in TERMS[1:]]
                rows.append((os.path.relpath(scene, ROOT), mode, s["seconds"], counts))
                print(f"{rows[-1][0]} {mode}: {s['seconds']:.2f} s", file=sys.stderr)
    a = np.array([r[3] for r in rows]) * 1e-9
    t = np.array([r[2] for r in rows])
    ns = nnls(a / t[:, None], np.ones(len(t)))
    for (name, _), v in zip(TERMS, ns):
        print(f"const {name}: f64 = {v:.0f}.0;")
    pred = a @ ns
    err = pred / t - 1
    print(f"\nrelative error of the fit: rms {np.sqrt(np.mean(err ** 2)):.3f}, "
          f"worst {np.max(np.abs(err)):.3f}\n")
    print("| scene | guided / unguided cost, measured | predicted |")
    print("|---|---|---|")
    by = {(r[0], r[1]): (r[2] / r[3][0], p / r[3][0]) for r, p in zip(rows, pred)}
    for scene in sorted({r[0] for r in rows}):
        (mf, pf), (mo, po) = by[(scene, "full")], by[(scene, "off")]
        print(f"| {scene} | {mf / mo:.2f} | {pf / po:.2f} |")


if __name__ == "__main__":
    main()
