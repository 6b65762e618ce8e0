#!/usr/bin/env python3
"""Renders a Mitsuba 3 XML scene with Mitsuba 3's `volpath` for a wall-clock budget and measures
it against a zerovar reference, for bench/run.sh's Mitsuba column.

Usage:
    python3 tools/mitsuba-bench.py SCENE.xml --reference REF.exr --seconds S
        [--threads T] [--variant V] [--integrator NAME] [--pass-spp K] [--seed S] [--trim F]
        [--block B] [--out IMAGE.exr] [--json RESULT.json] [--csv RESULT.csv]

The budget starts before `import mitsuba` and so includes Python's start of Mitsuba, the scene
load and, with an LLVM variant, the JIT compilation of the first pass; these are reported
separately (`load_seconds`, `first_pass_seconds`). Passes of K samples per pixel (default 4),
each with its own seed, are accumulated until the budget is spent: as zerovar's `--time` does, a
pass is started only while the time left exceeds the time one sample per pixel took, and the
last pass is shortened to fit. Pass k of a run with `--seed S` (default 0) uses Mitsuba's seed
S * 1000003 + k, so that runs with different S share no pass (a run has far fewer than 1000003
passes) and give independent estimates, as bench/run.sh's several seeds need.

Variant: `auto` (the default) tries `llvm_ad_rgb` and falls back to `scalar_rgb` if the LLVM
backend cannot start or crashes (Dr.Jit needs a shared libLLVM; LLVM 14 and 15 abort on the
kernels Mitsuba 3.9 emits, so `auto` points DRJIT_LIBLLVM_PATH at the newest libLLVM found, if
the variable is unset). Which variant ran is printed and recorded.

Metrics are zerovar's (lab/src/metrics.rs), computed the same way: per pixel and channel, relMSE =
(I - R)^2 / (R^2 + 1e-3), MSE = (I - R)^2, MAPE = |I - R| / (|R| + 1e-3), SMAPE = 2 |I - R| /
(|I| + |R| + 1e-3), each averaged over the pixels and over channels for `all`. `error` counts
every pixel; `trimmed` is the same with the fraction `--trim` of pixels with the largest value
left out (per metric and channel), as `zerovar compare` reports both. The image is compared as
32-bit floats, as zerovar compares its own.

If the reference has a standard-error layer (`zerovar reference` writes one), the tool also
reports the agreement of the two renderers by z-scores, as tests/mitsuba.rs does: per
pixel-channel z = (Mitsuba - reference) / sqrt(se_M^2 + se_R^2), where se_M is the standard error
of Mitsuba's mean estimated from the spread of its passes; the fraction of |z| > 3 (0.27% for
two unbiased renderers) and the pooled difference of the whole image and of each quadrant in
units of its standard error (per channel; the channel furthest from 0 is reported, since the
channels of a pixel come from the same paths and are not independent). `--block B` first
averages B x B pixel blocks of both images (standard errors combined accordingly), which makes
z closer to normal where single pixels are heavy-tailed.

Output: a summary on stdout, one JSON object (`--json`, also printed as the last stdout line) and
optionally a CSV line with header (`--csv`), and the image (`--out`, default SCENE-mitsuba.exr
beside the reference) as an EXR with the mean (R, G, B) and its standard error (stderr.R, ...).
"""

import argparse
import glob
import json
import os
import re
import subprocess
import sys
import time

EPSILON = 1e-3  # zerovar's metrics::EPSILON
LLVM_VARIANT = "llvm_ad_rgb"
SCALAR_VARIANT = "scalar_rgb"
SEED_STRIDE = 1000003  # seeds of run S: S * SEED_STRIDE + pass; more passes than this never fit a budget


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", help="Mitsuba 3 XML scene")
    p.add_argument("--reference", required=True, help="reference EXR (zerovar reference)")
    p.add_argument("--seconds", type=float, required=True, help="wall-clock budget")
    p.add_argument("--threads", type=int, default=os.cpu_count(), help="threads (default: all cores)")
    p.add_argument("--variant", default="auto", help="Mitsuba variant, or auto (llvm_ad_rgb, else scalar_rgb)")
    p.add_argument("--integrator", help="set the scene's $integrator default (the bench scenes: volpath, "
                   "or volpathmis for spectral MIS in chromatic media)")
    p.add_argument("--pass-spp", type=int, default=4, help="samples per pixel of each pass (default 4)")
    p.add_argument("--seed", type=int, default=0, help="run seed S: pass k uses Mitsuba's seed S * 1000003 + k (default 0)")
    p.add_argument("--trim", type=float, default=0.0, help="fraction of worst pixels the `trimmed` metrics drop, "
                   "per metric and channel (default 0; `error` counts every pixel)")
    p.add_argument("--block", type=int, default=1, help="average BxB pixel blocks for the z-scores (default 1)")
    p.add_argument("--out", help="output EXR (default: beside the reference, <scene>-mitsuba.exr)")
    p.add_argument("--json", help="write the result as JSON to this file")
    p.add_argument("--csv", help="write the result as a CSV header and line to this file")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    errors = []
    if a.seconds <= 0:
        errors.append(f"--seconds {a.seconds}: give a positive budget")
    if a.threads is None or a.threads < 1:
        errors.append(f"--threads {a.threads}: give at least one thread")
    if a.pass_spp < 1:
        errors.append(f"--pass-spp {a.pass_spp}: give at least one sample per pixel")
    # Mitsuba's seed is a 32-bit unsigned integer: S * 1000003 plus the passes must fit.
    if not 0 <= a.seed * SEED_STRIDE + SEED_STRIDE - 1 < 2**32:
        errors.append(f"--seed {a.seed}: give a seed from 0 to {2**32 // SEED_STRIDE - 1}")
    if not 0.0 <= a.trim < 0.5:
        errors.append(f"--trim {a.trim}: the trimmed fraction must lie in [0, 0.5)")
    if a.block < 1:
        errors.append(f"--block {a.block}: give a block size of at least 1")
    for path, what in ((a.scene, "scene"), (a.reference, "reference")):
        if not os.path.isfile(path):
            errors.append(f"{path}: no such {what} file")
    if errors:
        p.error("; ".join(errors))
    if a.out is None:
        stem = os.path.splitext(os.path.basename(a.scene))[0]
        a.out = os.path.join(os.path.dirname(os.path.abspath(a.reference)), f"{stem}-mitsuba.exr")
    return a


def newest_libllvm():
    """The shared libLLVM with the highest major version in the usual places, or None."""
    found = []
    patterns = ["/usr/lib/*/libLLVM-*.so*", "/usr/lib/libLLVM-*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*",
                "/usr/local/lib/libLLVM*.so*"]
    for pattern in patterns:
        for path in glob.glob(pattern):
            m = re.search(r"(?:libLLVM-|llvm-)(\d+)", path)
            if m:
                found.append((int(m.group(1)), path))
    return max(found)[1] if found else None


# ---------------------------------------------------------------------------------------------
# Metrics, exactly as lab/src/metrics.rs computes them.


def metric(image, reference, trim, f):
    """One metric per channel and its mean over channels (zerovar's `metrics::metric`)."""
    import numpy as np

    n = image.shape[0]
    keep = n - min(int(np.floor(n * trim)), max(n - 1, 0))
    rgb = []
    for c in range(3):
        values = f(image[:, c].astype(np.float64), reference[:, c].astype(np.float64))
        if keep < n:
            values = np.partition(values, keep)[:keep]
        rgb.append(float(values.sum() / max(keep, 1)))
    return {"rgb": rgb, "all": sum(rgb) / 3.0}


def reference_noise(image, reference, reference_se, trim):
    """The reference's own share of relMSE and the excess over it (zerovar's
    `metrics::compare_with_reference_noise`): per channel the pixels relMSE keeps, the mean of
    s^2 / (R^2 + eps) over them, and the standard error of the excess over pixels."""
    import numpy as np

    n = image.shape[0]
    keep = n - min(int(np.floor(n * trim)), max(n - 1, 0))
    rel, share, se = [], [], []
    for c in range(3):
        r = reference[:, c].astype(np.float64)
        d = r * r + EPSILON
        values = (image[:, c].astype(np.float64) - r) ** 2 / d
        floors = reference_se[:, c].astype(np.float64) ** 2 / d
        if keep < n:
            kept = np.argpartition(values, keep)[:keep]
            values, floors = values[kept], floors[kept]
        rel.append(values.mean())
        share.append(floors.mean())
        se.append(float(np.sqrt((values - floors).var(ddof=1) / keep)) if keep > 1 else 0.0)
    per = lambda v: {"rgb": [float(x) for x in v], "all": float(sum(v) / 3.0)}
    return {"share": per(share), "excess": per([a - b for a, b in zip(rel, share)]),
            "excess_std_error": sum(se) / 3.0}


def image_error(image, reference, trim, reference_se=None):
    """relMSE, MSE, MAPE and SMAPE of `image` against `reference` (N x 3 float32 arrays), and
    with the reference's standard error the reference noise's share of relMSE."""
    import numpy as np

    if image.shape != reference.shape or image.size == 0:
        raise ValueError(
            f"the image has {image.shape[0]} pixels but the reference has {reference.shape[0]}; "
            "render both at the same resolution")
    return {
        "rel_mse": metric(image, reference, trim, lambda i, r: (i - r) ** 2 / (r * r + EPSILON)),
        "reference_noise": (None if reference_se is None
                            else reference_noise(image, reference, reference_se, trim)),
        "mse": metric(image, reference, trim, lambda i, r: (i - r) ** 2),
        "mape": metric(image, reference, trim, lambda i, r: np.abs(i - r) / (np.abs(r) + EPSILON)),
        "smape": metric(image, reference, trim,
                        lambda i, r: 2.0 * np.abs(i - r) / (np.abs(i) + np.abs(r) + EPSILON)),
    }


def agreement(mean, se, ref, ref_se, block):
    """z-score statistics of two images with standard errors (H x W x 3), as tests/mitsuba.rs."""
    import numpy as np

    def down(a, square):
        h, w = a.shape[0] // block * block, a.shape[1] // block * block
        a = a[:h, :w].reshape(h // block, block, w // block, block, 3)
        if square:  # standard error of a block mean
            return np.sqrt((a * a).sum(axis=(1, 3))) / (block * block)
        return a.mean(axis=(1, 3))

    m, s, r, rs = down(mean, False), down(se, True), down(ref, False), down(ref_se, True)
    d = m - r
    var = s * s + rs * rs
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(var > 1e-14, d / np.sqrt(var),
                     np.where(np.abs(d) <= 1e-5 * np.maximum(np.abs(r), 1.0), 0.0, np.sign(d) * 1e3))
    h, w = d.shape[:2]

    def pooled(sl):
        # Per channel, then the channel furthest from 0: the channels of one pixel come from
        # the same paths (identical in a grey scene), so pooling them would overstate z.
        zs = []
        for c in range(3):
            v = var[sl + (c,)].sum()
            zs.append(float(d[sl + (c,)].sum() / np.sqrt(v)) if v > 0 else 0.0)
        return max(zs, key=abs)

    quads = [pooled((slice(y0, y1), slice(x0, x1)))
             for (y0, y1) in ((0, h // 2), (h // 2, h)) for (x0, x1) in ((0, w // 2), (w // 2, w))]
    return {
        "block": block,
        "outliers": float((np.abs(z) > 3).mean()),
        "mean_z": float(z.mean() * np.sqrt(z.size)),
        "whole": pooled((slice(None), slice(None))),
        "quadrants": quads,
        "ratio_of_sums": float(m.sum() / r.sum()) if r.sum() != 0 else float("nan"),
    }


def read_exr(mi, path):
    """Mean and standard error (None if absent) of an EXR as H x W x 3 float32 arrays.

    `zerovar reference` writes the standard error as a second part (layer) named `stderr`,
    which Mitsuba's Bitmap does not read: that takes the OpenEXR module (pip install OpenEXR).
    Without it only the mean is read, and the agreement check is skipped."""
    import numpy as np

    try:
        import OpenEXR
    except ImportError:
        OpenEXR = None
    if OpenEXR is None:
        bitmap = mi.Bitmap(path)
        names = [f.name for f in bitmap.struct_()]
        data = np.array(bitmap, copy=False).astype(np.float32).reshape(
            bitmap.height(), bitmap.width(), -1)
        channels = {n: data[:, :, i] for i, n in enumerate(names)}
    else:
        channels = {}
        with OpenEXR.File(path, separate_channels=True) as f:
            for part in f.parts:
                prefix = "stderr." if part.name() == "stderr" else ""
                for name, channel in part.channels.items():
                    channels[prefix + name] = np.asarray(channel.pixels, dtype=np.float32)

    def rgb(prefix):
        keys = [prefix + c for c in "RGB"]
        if all(k in channels for k in keys):
            return np.stack([channels[k] for k in keys], axis=2)
        return None

    mean = rgb("")
    if mean is None:
        raise SystemExit(f"{path}: no R, G, B channels (it has {', '.join(channels) or 'none'})")
    return mean, rgb("stderr."), OpenEXR is not None


# ---------------------------------------------------------------------------------------------
# The budgeted render (in a worker process, so that a crash of the LLVM backend can be caught).


def worker(a):
    start = time.perf_counter()
    import numpy as np
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(a.variant)
    dr.set_thread_count(a.threads)
    scene = mi.load_file(a.scene, **({"integrator": a.integrator} if a.integrator else {}))
    ref, ref_se, have_openexr = read_exr(mi, a.reference)
    size = scene.sensors()[0].film().size()
    if ref.shape[:2] != (size[1], size[0]):
        raise SystemExit(f"{a.reference}: the reference is {ref.shape[1]}x{ref.shape[0]} but "
                         f"{a.scene} renders {size[0]}x{size[1]}; render both at the same "
                         "resolution")
    load_seconds = time.perf_counter() - start
    budget = a.seconds
    total = None
    total_sq = None
    spp = 0
    passes = 0
    first_pass_seconds = None
    per_spp = None
    while True:
        elapsed = time.perf_counter() - start
        left = budget - elapsed
        if passes > 0 and left <= per_spp:
            break
        k = a.pass_spp if per_spp is None else int(min(a.pass_spp, max(1, left // per_spp)))
        t0 = time.perf_counter()
        img = np.array(mi.render(scene, spp=k, seed=a.seed * SEED_STRIDE + passes),
                       dtype=np.float64)[:, :, :3]
        dt = time.perf_counter() - t0
        if passes <= 1:
            # The first pass includes JIT compilation: the second replaces its timing.
            per_spp = dt / k
            if passes == 0:
                first_pass_seconds = dt
        else:
            per_spp = 0.5 * (per_spp + dt / k)
        total = k * img if total is None else total + k * img
        total_sq = k * img * img if total_sq is None else total_sq + k * img * img
        spp += k
        passes += 1
        if passes == 1 and time.perf_counter() - start >= budget:
            break
    seconds = time.perf_counter() - start
    mean = total / spp
    if passes > 1:
        # Each pass is the mean of k_i samples: sum k_i (img_i - mean)^2 / (P - 1) estimates the
        # per-sample variance, and the mean of spp samples has that over spp.
        var = np.maximum(total_sq - spp * mean * mean, 0.0) / (passes - 1)
        stderr = np.sqrt(var / spp)
    else:
        stderr = np.full_like(mean, np.nan)
    data = np.concatenate([mean, stderr], axis=2).astype(np.float32)
    mi.Bitmap(data, pixel_format=mi.Bitmap.PixelFormat.MultiChannel,
              channel_names=["R", "G", "B", "stderr.R", "stderr.G", "stderr.B"]).write(a.out)
    image32 = mean.astype(np.float32).reshape(-1, 3)
    ref32 = ref.reshape(-1, 3)
    ref_se32 = None if ref_se is None else ref_se.reshape(-1, 3)
    result = {
        "renderer": "mitsuba3",
        "mitsuba": mi.__version__,
        "variant": a.variant,
        "integrator": str(scene.integrator()).split("[")[0],
        "scene": a.scene,
        "reference": a.reference,
        "budget_seconds": budget,
        "seconds": seconds,
        "load_seconds": load_seconds,
        "first_pass_seconds": first_pass_seconds,
        "threads": a.threads,
        "spp": spp,
        "passes": passes,
        "seed": a.seed,
        "trim": a.trim,
        "error": image_error(image32, ref32, 0.0, ref_se32),
        "trimmed": image_error(image32, ref32, a.trim, ref_se32),
        "image": a.out,
    }
    if ref_se is not None and passes > 1:
        result["agreement"] = agreement(mean, stderr, ref.astype(np.float64),
                                        ref_se.astype(np.float64), a.block)
    elif not have_openexr:
        result["agreement_skipped"] = "no OpenEXR module to read the reference's stderr layer (pip install OpenEXR)"
    elif passes < 2:
        result["agreement_skipped"] = "one pass only: no standard error for Mitsuba's image"
    else:
        result["agreement_skipped"] = "the reference has no standard-error layer"
    return result


def report(result, a):
    e = result["error"]
    t = result["trimmed"]
    print(f"{result['scene']}: Mitsuba {result['mitsuba']} {result['variant']} "
          f"({result['integrator']}), {result['threads']} threads")
    print(f"  {result['seconds']:.2f} s of {result['budget_seconds']:.2f} s: load "
          f"{result['load_seconds']:.2f} s, first pass (JIT included) "
          f"{result['first_pass_seconds']:.2f} s; {result['spp']} spp in {result['passes']} passes "
          f"(seed {result['seed']})")
    print(f"  relMSE {e['rel_mse']['all']:.4e} ({t['rel_mse']['all']:.4e} without the worst "
          f"{100 * result['trim']:g}%)  MSE {e['mse']['all']:.4e}  MAPE {e['mape']['all']:.4f}  "
          f"SMAPE {e['smape']['all']:.4f}")
    n = e.get("reference_noise")
    if n:
        print(f"  relMSE less the reference's noise {n['excess']['all']:.4e} ± "
              f"{n['excess_std_error']:.1e} (the noise adds {n['share']['all']:.4e})")
    g = result.get("agreement")
    if "agreement_skipped" in result:
        print(f"  agreement not checked: {result['agreement_skipped']}")
    if g:
        q = " ".join(f"{v:+.2f}" for v in g["quadrants"])
        print(f"  agreement ({g['block']}x{g['block']} blocks): |z| > 3 in {100 * g['outliers']:.2f}%, "
              f"pooled z {g['whole']:+.2f}, quadrants {q}, mean z {g['mean_z']:+.1f}/sqrt(N), "
              f"sum ratio {g['ratio_of_sums']:.4f}")
    print(f"  image: {result['image']}")
    line = json.dumps(result)
    if a.json:
        with open(a.json, "w") as f:
            f.write(line + "\n")
    if a.csv:
        cols = ["scene", "variant", "threads", "budget_seconds", "seconds", "load_seconds",
                "first_pass_seconds", "spp", "passes", "seed", "trim"]
        metrics = ["rel_mse", "mse", "mape", "smape"]
        with open(a.csv, "w") as f:
            f.write(",".join(cols + metrics + [m + "_trimmed" for m in metrics]) + "\n")
            f.write(",".join([str(result[c]) for c in cols] + [repr(e[m]["all"]) for m in metrics]
                             + [repr(t[m]["all"]) for m in metrics]) + "\n")
    print(line)


def main(argv):
    a = parse_args(argv)
    if a.worker:
        print("RESULT " + json.dumps(worker(a)), flush=True)
        return 0
    variants = [LLVM_VARIANT, SCALAR_VARIANT] if a.variant == "auto" else [a.variant]
    env = dict(os.environ)
    if a.variant in ("auto",) or a.variant.startswith("llvm"):
        if "DRJIT_LIBLLVM_PATH" not in env:
            lib = newest_libllvm()
            if lib:
                env["DRJIT_LIBLLVM_PATH"] = lib
    notes = []
    for variant in variants:
        args = [a.scene, "--reference", a.reference, "--seconds", str(a.seconds), "--threads",
                str(a.threads), "--variant", variant, "--pass-spp", str(a.pass_spp), "--seed",
                str(a.seed), "--trim", str(a.trim), "--block", str(a.block), "--out", a.out,
                "--worker"]
        if a.integrator:
            args += ["--integrator", a.integrator]
        proc = subprocess.run([sys.executable, os.path.abspath(__file__)] + args, env=env,
                              capture_output=True, text=True)
        lines = [l for l in proc.stdout.splitlines() if l.startswith("RESULT ")]
        if proc.returncode == 0 and lines:
            result = json.loads(lines[-1][len("RESULT "):])
            if variant.startswith("llvm"):
                result["libllvm"] = env.get("DRJIT_LIBLLVM_PATH", "(Dr.Jit's default search)")
            result["notes"] = notes
            for n in notes:
                print(n, file=sys.stderr)
            report(result, a)
            return 0
        err = [l for l in proc.stderr.splitlines() if l.strip()]
        why = next((l for l in err if "LLVM ERROR" in l), err[-1] if err else f"exit status {proc.returncode}")
        backend = proc.returncode < 0 or any("LLVM" in l or "jit_" in l for l in err)
        if not backend:  # not the variant's fault: the same error would follow with any
            sys.stderr.write(proc.stderr)
            return 1
        notes.append(f"variant {variant} failed ({why.strip()[:200]})")
        if variant != variants[-1]:
            notes[-1] += f"; falling back to {variants[variants.index(variant) + 1]}"
        else:
            sys.stderr.write(proc.stderr)
    for n in notes:
        print(n, file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
