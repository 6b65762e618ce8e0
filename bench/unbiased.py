#!/usr/bin/env python3
"""The high-power agreement run (bench/unbiased.sh): for every bench scene and every guiding
mode, the image mean and 8x8-block means of guided renders against unguided ones, over enough
seeds that the relative standard error of the difference of image means falls to the target.

Usage: python3 bench/unbiased.py ZEROVAR [--target 0.002] [--run-seconds 0.5]
           [--scene-seconds 300] [--modes directions,distances,rr,full,auto] [--scenes a,b]
           [--results bench/RESULTS.md]

Per scene, one unguided render of 4 spp times the work; each run then renders SPP samples per
pixel (a power of two, 32 to 4096, chosen so that an unguided run takes about --run-seconds),
and MIN_ROUNDS rounds of runs follow, one per method (unguided and each mode) with seeds 1, 2,
.... Then, until every mode's relative standard error (of its mean minus unguided's, over
unguided's) is at most --target or the scene has taken --scene-seconds, the next run goes to
the method whose run lowers the unfinished modes' squared standard errors most per second (the
unguided runs serve every mode, so where unguided sampling is the noisy one it gets most runs).
Every run is an independent unbiased estimate, so the difference of the means over runs has
mean zero and a standard error taken from the spread of the runs; z is the difference over it,
under Student's t with the fewer of the two methods' runs less one degrees of freedom (no more
than Welch's, so never a z too large). Per channel, the reported z is the channel furthest
from zero. Blocks: per 8x8-pixel block and channel the same z; the table gives the largest
|z| over blocks and how many exceed 4 (with N blocks x 3 channels, a normal z exceeds 4 about
6e-5 N times), and the z of the whole image is what decides: a |z| beyond 4 is a bug to find.

Needs numpy and OpenEXR (bench/unbiased.sh installs them). Writes the section "Unbiasedness"
of --results (replacing an earlier one) and prints it.
"""

import argparse
import datetime
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import OpenEXR
import Imath

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tables  # noqa: E402  (bench/tables.py: the section writer RESULTS.md shares)

BLOCK = 8
# Fewest rounds (runs per mode) per scene: with 8, a t beyond 4 has p 0.005 rather than 0.057
# with 3, and the conversion to z below takes care of the rest.
MIN_ROUNDS = 8
# Relative rounding of an image value (32-bit floats, averaged over samples and combined).
ROUNDING = 1e-6
# Gauss-Legendre nodes and weights on (0, 1), for Student's t integrals.
_X, _W = np.polynomial.legendre.leggauss(96)
_X, _W = 0.5 * (_X + 1.0), 0.5 * _W


def t_two_sided(t, dof):
    """P(|T| > |t|) for Student's t with `dof` degrees of freedom, elementwise."""
    t = np.abs(np.asarray(t, dtype=np.float64))
    c = math.exp(math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2)) / math.sqrt(dof * math.pi)
    dens = lambda x: c * (1.0 + x * x / dof) ** (-(dof + 1) / 2)
    low = np.minimum(t, 1.0)[..., None]
    # Up to min(t, 1) directly; beyond 1 with x = t / s, s in (0, 1], which keeps the
    # integrand smooth however far the tail goes.
    inner = (dens(low * _X) * low * _W).sum(-1)
    big = np.maximum(t, 1.0)[..., None]
    outer = (dens(big / _X) * big / (_X * _X) * _W).sum(-1)
    half = (dens(1.0 / _X) / (_X * _X) * _W).sum() + (dens(_X) * _W).sum()  # 0 to infinity
    tail = np.where(t <= 1.0, half - inner, outer)
    return np.clip(2.0 * tail, 0.0, 1.0)


def normal_equivalent(t, dof):
    """The normal deviate with the two-sided probability of `t` under Student's t, with t's
    sign (bisection on erfc, elementwise)."""
    p = t_two_sided(t, dof)
    lo, hi = np.zeros_like(p), np.full_like(p, 40.0)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        tail = np.vectorize(lambda z: math.erfc(z / math.sqrt(2.0)))(mid)
        lo, hi = np.where(tail > p, mid, lo), np.where(tail > p, hi, mid)
    return np.sign(t) * 0.5 * (lo + hi)


def load(path):
    f = OpenEXR.InputFile(path)
    dw = f.header()["dataWindow"]
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    pt = Imath.PixelType(Imath.PixelType.FLOAT)
    return np.stack([np.frombuffer(f.channel(c, pt), dtype=np.float32).reshape(h, w)
                     for c in "RGB"], -1).astype(np.float64)


def blocks(img):
    h, w, _ = img.shape
    hb, wb = h // BLOCK, w // BLOCK
    return img[:hb * BLOCK, :wb * BLOCK].reshape(hb, BLOCK, wb, BLOCK, 3).mean(axis=(1, 3))


def render(zerovar, scene, mode, spp, seed, out):
    stats = out + ".json"
    cmd = [zerovar, "render", scene, "--guiding", mode, "--spp", str(spp), "--seed", str(seed),
           "-o", out, "--stats", stats, "--quiet"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    with open(stats) as f:
        seconds = json.load(f)["seconds"]
    img = load(out)
    return img, seconds


class Runs:
    """Per-run image means and block means of one mode."""

    def __init__(self):
        self.means = []
        self.blocks = []
        self.seconds = 0.0

    def add(self, img, seconds):
        self.means.append(img.reshape(-1, 3).mean(0))
        self.blocks.append(blocks(img))
        self.seconds += seconds

    def stats(self, values):
        v = np.array(values)
        return v.mean(0), v.var(0, ddof=1) / len(v)


def compare(guided, unguided):
    """(relative difference, relative standard error, z) of the image mean, per channel; and
    the block z statistics."""
    gm, gv = guided.stats(guided.means)
    um, uv = unguided.stats(unguided.means)
    se = np.sqrt(gv + uv)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(se > 0, (gm - um) / se, 0.0)
        rel = np.where(um > 0, (gm - um) / um, 0.0)
        rel_se = np.where(um > 0, se / um, 0.0)
    bm, bv = guided.stats(guided.blocks)
    ubm, ubv = unguided.stats(unguided.blocks)
    # A floor of float rounding (blocks of constant background are equal in every run up to
    # the last bits, and a zero spread would turn those bits into any z).
    bse = np.sqrt(bv + ubv + (ROUNDING * ubm) ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        bz = np.where(bse > 0, (bm - ubm) / bse, 0.0)
    dof = min(len(guided.means), len(unguided.means)) - 1
    return rel, rel_se, normal_equivalent(z, dof), normal_equivalent(bz, dof)


def next_method(runs, modes, target):
    """The method whose next run lowers the squared relative standard errors of the modes not
    yet at `target` most per second of its runs, or None when every mode is there."""
    off = runs["off"]
    um = np.abs(np.array(off.means).mean(0))
    um = np.where(um > 0, um, np.inf)
    def shares(r):
        # A run's variance over the mean squared, per channel, and what one more run removes.
        v = np.array(r.means).var(0, ddof=1) / um ** 2
        n = len(r.means)
        return v / n, v / n - v / (n + 1)
    off_se2, off_gain = shares(off)
    gains = {m: 0.0 for m in runs}
    for m in modes:
        se2, gain = shares(runs[m])
        total = se2 + off_se2
        c = int(np.argmax(total))
        if total[c] <= target ** 2:
            continue
        gains[m] += gain[c]
        gains["off"] += off_gain[c]
    if all(g == 0.0 for g in gains.values()):
        return None
    return max(gains, key=lambda m: gains[m] / (runs[m].seconds / len(runs[m].means)))


def worst(values, z):
    """The channel whose z is furthest from zero."""
    c = int(np.argmax(np.abs(z)))
    return values[c], c


def scenes_of(bench):
    names = sorted({os.path.splitext(f)[0] for f in os.listdir(bench) if f.endswith((".toml", ".xml"))})
    out = []
    for n in names:
        toml = os.path.join(bench, n + ".toml")
        out.append((n, toml if os.path.exists(toml) else os.path.join(bench, n + ".xml")))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("zerovar")
    p.add_argument("--target", type=float, default=0.002)
    p.add_argument("--run-seconds", type=float, default=0.5)
    p.add_argument("--scene-seconds", type=float, default=300)
    p.add_argument("--modes", default="directions,distances,rr,full,auto")
    p.add_argument("--scenes", help="comma-separated bench scene names (default: all)")
    p.add_argument("--results", default="bench/RESULTS.md")
    a = p.parse_args()
    modes = a.modes.split(",")
    scenes = scenes_of("scenes/bench")
    if a.scenes:
        wanted = a.scenes.split(",")
        scenes = [s for s in scenes if s[0] in wanted]
    rows = []
    tmp = tempfile.mkdtemp(prefix="zerovar-unbiased-")
    out = os.path.join(tmp, "img.exr")
    for name, scene in scenes:
        start = time.time()
        _, t4 = render(a.zerovar, scene, "off", 4, 0, out)
        spp = int(min(4096, max(32, 2 ** round(np.log2(max(4 * a.run_seconds / max(t4, 1e-3), 1))))))
        runs = {m: Runs() for m in ["off"] + modes}
        for seed in range(1, MIN_ROUNDS + 1):
            for m in runs:
                runs[m].add(*render(a.zerovar, scene, m, spp, seed, out))
        while time.time() - start <= a.scene_seconds:
            m = next_method(runs, modes, a.target)
            if m is None:
                break
            runs[m].add(*render(a.zerovar, scene, m, spp, len(runs[m].means) + 1, out))
        seed = len(runs["off"].means)
        for m in modes:
            rel, rel_se, z, bz = compare(runs[m], runs["off"])
            zc, c = worst(z, z)
            nb = bz.size
            rows.append({
                "scene": name, "mode": m, "spp": spp, "seeds": len(runs[m].means),
                "unguided": seed, "channel": "RGB"[c],
                "rel": rel[c], "rel_se": rel_se[c], "z": zc,
                "blocks": nb, "block_max": float(np.max(np.abs(bz))) if nb else 0.0,
                "block_over4": int(np.sum(np.abs(bz) > 4)),
                "reached": bool(np.max(rel_se) <= a.target),
                "largest_se": float(np.max(rel_se)),
            })
            r = rows[-1]
            print(f"{name:16s} {m:10s} {spp:5d} spp x {r['seeds']:3d} (unguided {seed}): diff {100 * r['rel']:+.3f}% "
                  f"+- {100 * r['rel_se']:.3f}% z {r['z']:+.2f} (largest standard error "
                  f"{100 * r['largest_se']:.3f}%)  blocks max |z| {r['block_max']:.1f}, "
                  f"{r['block_over4']} of {nb} over 4", file=sys.stderr)
    section = table(rows, a)
    print(section)
    tables.write_section(a.results, "Unbiasedness", section)


def table(rows, a):
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    lines = [
        "## Unbiasedness",
        "",
        f"`bench/unbiased.sh` on {date} at {commit}: per scene and guiding mode, the image mean of "
        "guided renders against unguided ones, each run an independent render of the same spp "
        f"(seeds 1, 2, ...), until the relative standard error of the difference is at most "
        f"{100 * a.target:.1f}% (or the scene's {a.scene_seconds:.0f} s are spent: `reached` says "
        "which); after 8 runs of each, a run goes where it lowers the standard errors most per "
        "second. z is the normal deviate with the two-sided probability of the difference over "
        "its standard error under Student's t with the fewer runs less one degrees of freedom. The channel shown "
        "is the one whose z is furthest from 0; blocks are 8x8 pixels, per channel (a normal z "
        "exceeds 4 in about 6e-5 of them).",
        "",
        "| scene | mode | spp x runs (unguided's) | guided - unguided | its standard error | z | reached | blocks: max abs z | blocks over 4 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        # The channel shown is the one furthest from 0; a run short of the target says how far.
        reached = "yes" if r["reached"] else f"no ({100 * r['largest_se']:.3f}% in a channel)"
        lines.append(
            f"| {r['scene']} | {r['mode']} | {r['spp']} x {r['seeds']} ({r['unguided']}) | {100 * r['rel']:+.3f}% ({r['channel']}) "
            f"| {100 * r['rel_se']:.3f}% | {r['z']:+.2f} | {reached} "
            f"| {r['block_max']:.1f} | {r['block_over4']} of {r['blocks']} |")
    bad = [r for r in rows if abs(r["z"]) > 4]
    lines.append("")
    lines.append(f"{len(bad)} of {len(rows)} scene-mode pairs with |z| > 4"
                 + (": " + ", ".join(f"{r['scene']} {r['mode']}" for r in bad) if bad else "."))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
