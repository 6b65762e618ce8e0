#!/usr/bin/env python3
"""The tables of bench/RESULTS.md, for bench/run.sh (Python's standard library only).

    python3 bench/tables.py summary OUT_DIR SCENES_DIR MITSUBA(0|1) [--held-out FILE] [--trim F]
        prints the summary: a table for the tuning set and one for the held-out set (the scenes
        FILE names, default bench/held-out.txt), a row per scene and method other than the
        first, each against the first (unguided) and against Mitsuba 3 (MITSUBA=1).
    python3 bench/tables.py scene OUT_DIR/<scene> SCENE.xml [--no-mitsuba] [--trim F]
        prints one scene's table: every method's runs (results.json from `zerovar compare
        --seeds`), Mitsuba 3's (mitsuba-<integrator>-<seed>.json from tools/mitsuba-bench.py),
        the convergence of the first seed and the renderers' agreement, or why Mitsuba is missing
        (mitsuba-<integrator>-<seed>.log).

The scenes of SCENES_DIR are its *.toml files and the *.xml files with no .toml of the same name
(bench/run.sh's rule). --trim is the fraction the trimmed relMSE left out (run.sh's 0.001); it
only labels the columns, the numbers are those of the JSON files.
"""

import argparse
import json
import math
import os
import pathlib

BENCH = pathlib.Path(__file__).resolve().parent
INTEGRATORS = ("volpath", "volpathmis")


def rust_e(x, digits=3):
    """A float as Rust's `{:.3e}` writes it (1.249e-1, not Python's 1.249e-01)."""
    if x is None:
        return "-"
    if not math.isfinite(x):
        return str(x)
    mantissa, exponent = f"{x:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def ratio(a, b, digits=2):
    """a / b for the tables, or "-" when either is missing or b is not positive."""
    if a is None or b is None or not b > 0 or not math.isfinite(a / b):
        return "-"
    return f"{a / b:.{digits}f}"


def median(values):
    """The median (the mean of the middle two for an even count), as `zerovar compare`'s Spread."""
    v = sorted(values)
    n = len(v)
    if n == 0:
        return None
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def spread(values, digits=3):
    """`median [min, max]`, as `zerovar compare`'s tables write a spread (one value: just it)."""
    v = [x for x in values if x is not None]
    if not v:
        return "-"
    if len(v) == 1:
        return rust_e(v[0], digits)
    return f"{rust_e(median(v), digits)} [{rust_e(min(v), digits - 1)}, {rust_e(max(v), digits - 1)}]"


def percent(trim):
    return f"{100 * trim:g}%"


def load_json(path):
    """A JSON file, or None if it is missing or unreadable (a run that died half-way)."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def last_line(path):
    try:
        lines = [l.strip() for l in path.read_text().splitlines() if l.strip()]
    except OSError:
        return None
    return lines[-1] if lines else None


def resolved(e):
    """Whether an ImageError's excess over the reference's noise stands out of its standard
    error, as zerovar's `ReferenceNoise::resolved`."""
    n = e.get("reference_noise") if e else None
    return n is not None and n["excess"]["all"] > 2.0 * n["excess_std_error"]


def scored(e, excess):
    """The relMSE the tables compare: less the reference's noise when `excess` (and known)."""
    if e is None:
        return None
    n = e.get("reference_noise")
    return n["excess"]["all"] if excess and n is not None else e["rel_mse"]["all"]


def write_section(path, heading, section):
    """Replaces the section `## heading` of the Markdown file `path` (up to the next `## `
    heading or the end) with `section`, or appends it; a missing file is created."""
    path = pathlib.Path(path)
    text = path.read_text() if path.exists() else ""
    lines = text.split("\n")
    start = next((i for i, l in enumerate(lines) if l.strip() == f"## {heading}"), None)
    if start is None:
        text = text.rstrip("\n") + "\n\n" + section
    else:
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")),
                   len(lines))
        rest = "\n".join(lines[end:])
        text = "\n".join(lines[:start]) + "\n" + section + ("\n" + rest if rest else "")
    path.write_text(text)


def scene_names(scenes_dir):
    """bench/run.sh's scenes: every *.toml, and every *.xml with no .toml of the same name."""
    names = {p.stem for p in scenes_dir.glob("*.toml")}
    names |= {p.stem for p in scenes_dir.glob("*.xml") if not p.with_suffix(".toml").exists()}
    return sorted(names)


def held_out_names(path):
    """The names of a held-out list: one a line, `#` starting a comment line."""
    try:
        text = path.read_text()
    except OSError:
        return None
    return [l.strip() for l in text.splitlines() if l.strip() and not l.strip().startswith("#")]


class Mitsuba:
    """One integrator's Mitsuba 3 runs on a scene (one JSON per seed)."""

    def __init__(self, out, integrator):
        """`out` None: Mitsuba did not run at all (files a former run left are not this run's)."""
        self.out = out
        self.integrator = integrator
        jsons = sorted(out.glob(f"mitsuba-{integrator}-*.json")) if out else []
        runs = [r for r in map(load_json, jsons) if r is not None and "error" in r]
        self.runs = sorted(runs, key=lambda r: r.get("seed", 0))
        self.logs = sorted(out.glob(f"mitsuba-{integrator}-*.log")) if out else []
        self.variants = sorted({r.get("variant", "?") for r in self.runs})
        # Only an LLVM (vectorised, JIT-compiled) variant is Mitsuba at its speed; the scalar
        # fallback is several times slower, so an equal-time ratio with it would say little.
        self.fallback = [v for v in self.variants if not v.startswith("llvm")]
        self.comparable = bool(self.runs) and not self.fallback

    @property
    def ran(self):
        """Whether it was asked for at all (a result or a log)."""
        return bool(self.runs or self.logs)

    def why_missing(self):
        for log in self.logs:
            line = last_line(log)
            if line:
                return line
        return f"no {self.out}/mitsuba-{self.integrator}-*.json or .log"

    def failed_seeds(self):
        """Runs with a log but no JSON (those that failed while others succeeded)."""
        done = {f"mitsuba-{self.integrator}-{r.get('seed', 0)}" for r in self.runs}
        return [l for l in self.logs if l.stem not in done]

    def label(self):
        if self.fallback:
            return f"{', '.join(self.fallback)} fallback, not comparable"
        return ", ".join(self.variants)

    def median(self, excess, key="error"):
        return median([scored(r.get(key), excess) for r in self.runs if r.get(key)])


class Scene:
    """One scene's results: zerovar's methods (results.json) and Mitsuba's runs."""

    def __init__(self, out, mitsuba=True):
        self.out = out
        self.methods = load_json(out / "results.json")
        if not isinstance(self.methods, list) or not self.methods:
            self.methods = None
        self.mitsuba = {i: Mitsuba(out if mitsuba else None, i) for i in INTEGRATORS}
        errors = [run["error"] for m in self.methods or [] for run in m["runs"]]
        errors += [r["error"] for mi in self.mitsuba.values() for r in mi.runs]
        # The excess over the reference's noise only where every run, zerovar's and Mitsuba's,
        # resolves it: a ratio of two differences of which one is noise would mean nothing.
        self.excess = bool(errors) and all(resolved(e) for e in errors)

    @property
    def chromatic(self):
        """Whether volpathmis was asked for (bench/run.sh does so for chromatic scenes)."""
        return self.mitsuba["volpathmis"].ran

    def values(self, m, key="error"):
        """A method's per-run relMSE on the scene's basis, in seed order."""
        return [scored(run.get(key), self.excess) for run in m["runs"]]

    def median(self, m, key="error"):
        return median([v for v in self.values(m, key) if v is not None])

    def basis(self):
        return "excess" if self.excess else "raw"


# ---------------------------------------------------------------------------------------------
# The summary.


def geometric_mean(values):
    v = [x for x in values if x is not None and x > 0 and math.isfinite(x)]
    return math.exp(sum(math.log(x) for x in v) / len(v)) if v else None


def summary_table(title, names, out, mitsuba, trim):
    """One table of the summary (markdown lines) for the scenes `names`."""
    cols = ["scene", "basis", "unguided relMSE", "method", "its relMSE",
            f"its relMSE without the worst {percent(trim)}", "error ratio", "max/min of its runs"]
    if mitsuba:
        cols += ["Mitsuba volpath relMSE", "Mitsuba / method", "Mitsuba volpathmis relMSE",
                 "volpathmis / method"]
    lines = ["", f"### {title}", ""]
    if not names:
        return lines + ["No scenes."]
    lines += ["| " + " | ".join(cols) + " |", "|---" * len(cols) + "|"]
    ratios = {}  # method name -> error ratios against the first method, one per scene
    base_name = None
    for name in names:
        s = Scene(out / name, mitsuba)
        if s.methods is None:
            cells = [name, "-", f"no results ({out / name}/results.json missing or unreadable)"]
            lines.append("| " + " | ".join(cells + ["-"] * (len(cols) - len(cells))) + " |")
            continue
        first = s.methods[0]
        base_name = first["name"]
        base = s.median(first)
        lead = [name, s.basis(), f"{spread(s.values(first))}"]
        m3 = []
        if mitsuba:
            for integrator in INTEGRATORS:
                mi = s.mitsuba[integrator]
                if integrator == "volpathmis" and not s.chromatic:
                    m3.append((None, "-"))
                elif not mi.runs:
                    twinless = "no Mitsuba 3 twin" in (mi.why_missing() or "")
                    m3.append((None, "no twin" if twinless else "failed" if mi.ran else "not run"))
                elif not mi.comparable:
                    m3.append((None, f"{rust_e(mi.median(s.excess))} ({mi.label()})"))
                else:
                    e3 = mi.median(s.excess)
                    asked = max(len(mi.logs), len(mi.runs))
                    seeds = "" if len(mi.runs) == asked else f" ({len(mi.runs)} of {asked} seeds)"
                    m3.append((e3, f"{rust_e(e3)}{seeds}"))
        if len(s.methods) == 1:
            cells = lead + ["(no other method)"]
            lines.append("| " + " | ".join(cells + ["-"] * (len(cols) - len(cells))) + " |")
        for m in s.methods[1:]:
            v = [x for x in s.values(m) if x is not None]
            e = median(v)
            trimmed = s.median(m, "trimmed")
            ratios.setdefault(m["name"], []).append(base / e if base and e and e > 0 else None)
            row = lead + [m["name"], spread(v), rust_e(trimmed), ratio(base, e),
                          ratio(max(v), min(v)) if v else "-"]
            for e3, text in m3:
                row += [text, ratio(e3, e)]
            lines.append("| " + " | ".join(row) + " |")
    means = []
    for method, rs in ratios.items():
        g = geometric_mean(rs)
        n = len([r for r in rs if r is not None and r > 0])
        means.append(f"{method} {'-' if g is None else f'{g:.2f}'} ({n} scene{'' if n == 1 else 's'})")
    if means:
        lines += ["", f"Geometric mean of the error ratios against {base_name}: "
                  + ", ".join(means) + "."]
    return lines


def summary(out, scenes_dir, mitsuba, held_out_file, trim):
    names = scene_names(scenes_dir)
    held = held_out_names(held_out_file)
    lines = ["", "## Summary", "",
             "Equal time, every method rendered once per seed. Each relMSE is the median over the",
             "seeds [smallest, largest]; error ratio is unguided's median over the method's (> 1:",
             "the method wins); max/min is the spread of the method's runs. `basis` says which",
             "relMSE a scene's figures are: `excess` is relMSE less the reference's own noise",
             "(its standard-error layer), used where every run on the scene, zerovar's and",
             "Mitsuba's, resolves it (excess > 2 standard errors); `raw` is relMSE as it is.",
             f"The relMSE without the worst {percent(trim)} of pixels (per channel, on the same",
             "basis) shows how much of the error is a few fireflies."]
    if mitsuba:
        lines += ["Mitsuba 3 runs `volpath` (and on chromatic scenes also `volpathmis`) on the",
                  "scene's XML twin at the same wall-clock time (scene load and JIT included) and",
                  "thread count, once per seed; its figure is the median over its seeds and",
                  "Mitsuba / method the ratio of the medians (> 1: the method has the smaller",
                  "error). A scalar_rgb fallback is shown but not compared: it is not Mitsuba at",
                  "its speed. Each scene's table gives the variant, spp and the renderers' agreement."]
    if held is None:
        lines += ["", f"No {held_out_file}: every scene counted as the tuning set."]
        held = []
    lines += ["", "The tuning set is what defaults are chosen on; the held-out set (the scenes",
              f"`{os.path.relpath(held_out_file)}` names) is reported and never tuned on."]
    tuning = [n for n in names if n not in held]
    held_here = [n for n in names if n in held]
    lines += summary_table("Tuning set", tuning, out, mitsuba, trim)
    lines += summary_table("Held-out set", held_here, out, mitsuba, trim)
    absent = [n for n in held if n not in names]
    if absent:
        lines += ["", f"Held out but not in {scenes_dir}: {', '.join(absent)}."]
    print("\n".join(lines))


# ---------------------------------------------------------------------------------------------
# One scene's table.


def convergence(s, m):
    """The first seed's relMSE at the checkpoints and its log-log slope against seconds."""
    points = []
    for c in m.get("checkpoints", []):
        e = scored(c["error"], s.excess)
        if e is not None:
            points.append((c["fraction"], c["seconds"], e))
    text = ", ".join(f"{f:g}: {rust_e(e)}" for f, _, e in points)
    xy = [(math.log(t), math.log(e)) for _, t, e in points if t > 0 and e > 0]
    if len(xy) >= 2:
        mx = sum(x for x, _ in xy) / len(xy)
        my = sum(y for _, y in xy) / len(xy)
        sxx = sum((x - mx) ** 2 for x, _ in xy)
        if sxx > 0:
            slope = sum((x - mx) * (y - my) for x, y in xy) / sxx
            text += f" (slope {slope:+.2f})"
    return f"{m['name']} {text}"


def scene_table(out, xml, mitsuba, trim):
    s = Scene(out, mitsuba)
    if s.methods is None:
        print(f"No results: {out}/results.json is missing, unreadable or empty (`zerovar compare` "
              "did not finish).")
        return
    noisy = all(r["error"].get("reference_noise") for m in s.methods for r in m["runs"])
    m3s = [s.mitsuba[i] for i in INTEGRATORS if mitsuba and s.mitsuba[i].ran]
    compared = [mi for mi in m3s if mi.comparable]
    seeds = max(len(m["runs"]) for m in s.methods)
    excess = s.excess
    # The columns are on the scene's basis, as the summary's; the other relMSE beside them.
    label = "relMSE - noise" if excess else "relMSE"
    other = "relMSE" if excess else ("relMSE - noise" if noisy else None)
    cols = ["method", "seconds", "spp", f"{label} per seed", label]
    if other:
        cols.append(other)
    cols += [f"{label} without the worst {percent(trim)} per seed",
             f"{label} without the worst {percent(trim)}", "efficiency", "speed-up"]
    cols += [f"Mitsuba {mi.integrator} / this" for mi in compared]
    lines = ["| " + " | ".join(cols) + " |", "|---" * len(cols) + "|"]

    def per_seed(values):
        return ", ".join(rust_e(v) for v in values) if values else "-"

    def row(name, seconds, spp, errors, trimmed):
        """`errors` and `trimmed`: the ImageErrors of the runs (None where missing)."""
        values = [scored(e, excess) for e in errors]
        e = median([v for v in values if v is not None])
        r = [name, f"{seconds:.2f}" if seconds is not None else "-",
             f"{spp:.0f}" if spp is not None else "-", per_seed(values), spread(values)]
        if other:
            if excess:
                r.append(spread([x["rel_mse"]["all"] for x in errors]))
            else:  # a Mitsuba run may lack the noise where zerovar's have it
                r.append(spread([x["reference_noise"]["excess"]["all"] if x.get("reference_noise")
                                 else None for x in errors]))
        tv = [scored(t, excess) for t in trimmed if t is not None]
        r += [per_seed(tv), rust_e(median(tv))]
        eff = 1.0 / (e * seconds) if e and seconds and e > 0 and seconds > 0 else None
        return r, e, eff

    base_eff = None
    rows = []
    for m in s.methods:
        runs = m["runs"]
        r, e, eff = row(m["name"], median([x["seconds"] for x in runs]),
                        median([x["spp"] for x in runs]), [x["error"] for x in runs],
                        [x.get("trimmed") for x in runs])
        base_eff = eff if base_eff is None else base_eff
        r += [rust_e(eff, 4), ratio(eff, base_eff)]
        r += [ratio(mi.median(excess), e) for mi in compared]
        rows.append(r)
    for mi in m3s:
        if not mi.runs:
            continue
        r, e, eff = row(f"Mitsuba 3 {mi.integrator} ({mi.label()})",
                        median([x["seconds"] for x in mi.runs]), median([x["spp"] for x in mi.runs]),
                        [x["error"] for x in mi.runs], [x.get("trimmed") for x in mi.runs])
        r += [rust_e(eff, 4), ratio(eff, base_eff) if mi.comparable else "-"]
        r += ["-" for _ in compared]
        rows.append(r)
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    print("\n".join(lines))
    print()
    m3_seeds = ""
    if any(mi.runs for mi in m3s):
        m3_seeds = (" Mitsuba's seeds are 0, 1, ... (pass k of seed S uses Mitsuba's seed"
                    " S * 1000003 + k).")
    print(f"Per seed in seed order; medians over the seeds [smallest, largest] ({seeds} for zerovar, "
          f"from the scene's seed on).{m3_seeds} Seconds and spp are medians; efficiency is "
          "1 / (median relMSE x median seconds), training"
          + (" and (Mitsuba) scene load and JIT" if m3s else "") + " included; speed-up is "
          "against the first row"
          + ("; Mitsuba X / this is X's median relMSE over the row's (> 1: the row has the "
             "smaller error)." if compared else "."))
    first = s.methods[0]["runs"][0]["error"].get("reference_noise")
    if first:
        print()
        print(f"The reference's own noise adds {rust_e(first['share']['all'], 4)} to every relMSE; "
              + ("the figures here are relMSE less it (`relMSE - noise`: every run resolves its "
                 "excess), but for the `relMSE` column." if excess else
                 "the figures here are raw relMSE (some run's excess is not resolved above that "
                 "noise: a longer reference would resolve it), the `relMSE - noise` column aside."
                 if noisy else "the figures here are raw relMSE."))
    print()
    print("Convergence (the first seed's renders at fractions of the budget, relMSE"
          + (" less the reference's noise" if excess else "") + "; slope of log relMSE against "
          "log seconds, -1 for an unbiased method at a steady rate): "
          + "; ".join(convergence(s, m) for m in s.methods) + ".")
    if not mitsuba:
        return
    for integrator in INTEGRATORS:
        mi = s.mitsuba[integrator]
        if not mi.ran:
            if integrator == "volpath":
                print()
                print(f"Mitsuba 3 {integrator}: not run ({mi.why_missing()}).")
            continue
        print()
        if not mi.runs:
            print(f"Mitsuba 3 {integrator}: no result ({mi.why_missing()}).")
            continue
        r = mi.runs[0]
        note = (f"Mitsuba 3 {r.get('mitsuba', '?')} `{integrator}`, `{mi.label()}`, on `{xml}`, "
                f"{r.get('threads', '?')} threads, {len(mi.runs)} seed{'' if len(mi.runs) == 1 else 's'}"
                f" (the first: {r.get('load_seconds', float('nan')):.2f} s to load, "
                f"{r.get('first_pass_seconds', float('nan')):.2f} s for the first pass, JIT "
                f"included, {r.get('passes', '?')} passes).")
        notes = sorted({n for x in mi.runs for n in x.get("notes", [])})
        if notes:
            note += " Note: " + "; ".join(notes) + "."
        failed = mi.failed_seeds()
        if failed:
            note += (" Failed: " + "; ".join(f"{l.stem} ({last_line(l) or 'empty log'})" for l in failed)
                     + ".")
        g = r.get("agreement")
        if g:
            q = ", ".join(f"{v:+.2f}" for v in g["quadrants"])
            note += (f" Agreement of its first seed with the reference ({g['block']}x{g['block']}-pixel "
                     f"blocks): |z| > 3 in {100 * g['outliers']:.2f}% of block-channels (0.27% "
                     f"expected), pooled z {g['whole']:+.2f} (quadrants {q}).")
        elif r.get("agreement_skipped"):
            note += f" Agreement not checked: {r['agreement_skipped']}."
        print(note)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    a = sub.add_parser("summary", help="the summary tables")
    a.add_argument("out", type=pathlib.Path, help="bench/out")
    a.add_argument("scenes", type=pathlib.Path, help="scenes/bench")
    a.add_argument("mitsuba", choices=("0", "1"), help="1 if Mitsuba 3 ran")
    a.add_argument("--held-out", type=pathlib.Path, default=BENCH / "held-out.txt")
    a.add_argument("--trim", type=float, default=0.001)
    b = sub.add_parser("scene", help="one scene's table")
    b.add_argument("out", type=pathlib.Path, help="bench/out/<scene>")
    b.add_argument("xml", help="the scene's Mitsuba twin (named in the notes)")
    b.add_argument("--no-mitsuba", action="store_true", help="Mitsuba 3 did not run at all")
    b.add_argument("--trim", type=float, default=0.001)
    args = p.parse_args()
    if args.command == "summary":
        summary(args.out, args.scenes, args.mitsuba == "1", args.held_out, args.trim)
    else:
        scene_table(args.out, args.xml, not args.no_mitsuba, args.trim)


if __name__ == "__main__":
    main()
