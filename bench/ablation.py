#!/usr/bin/env python3
"""The section "Ablation" of bench/RESULTS.md, for bench/ablation.sh (standard library only).

    python3 bench/ablation.py OUT_DIR [--results bench/RESULTS.md] [--seconds S] [--seeds K]
        [--held-out bench/held-out.txt] [--commit C]

Reads OUT_DIR/<scene>/ablation/results.json (`zerovar compare` of the nine methods) for every
scene that has one and writes a table per scene: each method's relMSE (median over the seeds
[range]), without the worst 0.1% of pixels, and its ratio to full guiding's (> 1: the method
has the larger error; for a row that removes a decision from full guiding, > 1 means the
decision pays). A scene's figures are relMSE less the reference's own noise where every run on
it resolves that noise, raw relMSE otherwise (bench/tables.py's rule). Each table names the
date and commit of its run; the tables of scenes not in OUT_DIR are kept from the earlier
section (an ablation of a few scenes adds to it), and the section is printed.
"""

import argparse
import datetime
import pathlib
import re
import subprocess
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import tables  # noqa: E402  (bench/tables.py: the same formatting and noise rule)

WHAT = {
    "unguided": "no decision guided",
    "full": "every decision guided",
    "directions": "directions alone",
    "distances": "distances alone (extra collisions for delta lights)",
    "rr": "roulette and splitting alone",
    "no-directions": "full without directions",
    "no-distances": "full without distances",
    "no-rr": "full without roulette and splitting",
    "full-density": "full with the zero-variance collision density at distance alpha 0.5",
}


def scene_table(name, results, run):
    runs = [r for m in results for r in m["runs"]]
    excess = all(tables.resolved(r["error"]) for r in runs)
    by_name = {m["name"]: m for m in results}

    def med(m, key):
        return tables.median([tables.scored(r[key], excess) for r in m["runs"]])

    full = by_name.get("full")
    full_error = med(full, "error") if full else None
    lines = [
        f"### {name}",
        "",
        f"{run}; basis: {'relMSE less the reference noise' if excess else 'raw relMSE'}",
        "",
        "| method | what | spp | relMSE | without the worst 0.1% | / full |",
        "|---|---|---|---|---|---|",
    ]
    for m in results:
        spp = tables.median([r["spp"] for r in m["runs"]])
        errors = [tables.scored(r["error"], excess) for r in m["runs"]]
        lines.append(
            f"| {m['name']} | {WHAT.get(m['name'], '')} | {spp:.0f} | {tables.spread(errors)} "
            f"| {tables.rust_e(med(m, 'trimmed'))} | {tables.ratio(med(m, 'error'), full_error)} |"
        )
    return lines


def earlier_tables(path):
    """The scene tables of the section "Ablation" of the Markdown file `path`, by scene name,
    each starting with its date and commit (taken from the section's first paragraph for
    tables written before each table named its own)."""
    try:
        lines = pathlib.Path(path).read_text().split("\n")
    except OSError:
        return {}
    start = next((i for i, l in enumerate(lines) if l.strip() == "## Ablation"), None)
    if start is None:
        return {}
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")),
               len(lines))
    body = lines[start + 1:end]
    old = re.search(r" on (\d{4}-\d{2}-\d{2}) at (\w+):", " ".join(body))
    tables_by_name, current = {}, None
    for line in body:
        if line.startswith("### "):
            current = line[4:].replace(" (held out)", "").strip()
            tables_by_name[current] = [line]
        elif current is not None:
            if line.startswith("basis: ") and old:
                line = f"run on {old.group(1)} at {old.group(2)}; {line}"
            tables_by_name[current].append(line)
    return {k: "\n".join(v).rstrip("\n").split("\n") for k, v in tables_by_name.items()}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--results", default="bench/RESULTS.md")
    p.add_argument("--seconds", type=float, default=30)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--held-out", default="bench/held-out.txt")
    p.add_argument("--commit", help="the commit the runs' binary was built from (default HEAD)")
    p.add_argument("--fresh", help="comma-separated scenes run now (default: every scene in OUT); "
                   "the others keep their earlier tables, dates and commits")
    a = p.parse_args()
    held_out = set(tables.held_out_names(pathlib.Path(a.held_out)) or [])
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    commit = a.commit or subprocess.run(["git", "rev-parse", "--short", "HEAD"],
                                        capture_output=True, text=True).stdout.strip()
    fresh = sorted(f.parent.parent.name for f in pathlib.Path(a.out).glob("*/ablation/results.json"))
    if a.fresh:
        fresh = [n for n in fresh if n in a.fresh.split(",")]
    kept = {k: v for k, v in earlier_tables(a.results).items() if k not in fresh}
    scenes = sorted(set(fresh) | set(kept))
    lines = [
        "## Ablation",
        "",
        f"`bench/ablation.sh SECONDS SEEDS` (here {a.seconds:g} s and {a.seeds} seeds): each "
        "guided decision alone and each removed from full guiding, at equal time (training "
        "included), every method once per seed, against the scene's reference. `/ full` is the "
        "ratio of the method's median to full guiding's. Each table gives the date and commit "
        f"of its run. Scenes: {', '.join(scenes)}; a bench scene without a table here has not "
        "been ablated yet.",
        "",
    ]
    run = f"run on {date} at {commit}"
    for name in scenes:
        if name in kept:
            lines += kept[name] + [""]
            continue
        results = tables.load_json(pathlib.Path(a.out) / name / "ablation" / "results.json")
        if not results:
            continue
        title = f"{name} (held out)" if name in held_out else name
        lines += scene_table(title, results, run) + [""]
    section = "\n".join(lines).rstrip("\n") + "\n"
    print(section)
    tables.write_section(a.results, "Ablation", section)


if __name__ == "__main__":
    main()
