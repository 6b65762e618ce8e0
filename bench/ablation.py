#!/usr/bin/env python3
"""The section "Ablation" of bench/RESULTS.md, for bench/ablation.sh (standard library only).

    python3 bench/ablation.py OUT_DIR [--results bench/RESULTS.md] [--seconds S] [--seeds K]
        [--held-out bench/held-out.txt] [--commit C]

Reads OUT_DIR/<scene>/ablation/results.json (`zerovar compare` of the nine methods) for every
scene that has one and writes a table per scene: each method's relMSE (median over the seeds
[range]), without the worst 0.1% of pixels, and its ratio to full guiding's (> 1: the method
has the larger error; for a row that removes a decision from full guiding, > 1 means the
decision pays). A scene's figures are relMSE less the reference's own noise where every run on
it resolves that noise, raw relMSE otherwise (bench/tables.py's rule). The section replaces an
earlier one and is printed.
"""

import argparse
import datetime
import pathlib
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


def scene_table(name, results):
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
        f"basis: {'relMSE less the reference noise' if excess else 'raw relMSE'}",
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


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--results", default="bench/RESULTS.md")
    p.add_argument("--seconds", type=float, default=30)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--held-out", default="bench/held-out.txt")
    p.add_argument("--commit", help="the commit the runs' binary was built from (default HEAD)")
    a = p.parse_args()
    held_out = set(tables.held_out_names(pathlib.Path(a.held_out)) or [])
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    commit = a.commit or subprocess.run(["git", "rev-parse", "--short", "HEAD"],
                                        capture_output=True, text=True).stdout.strip()
    scenes = sorted(f.parent.parent.name for f in pathlib.Path(a.out).glob("*/ablation/results.json"))
    lines = [
        "## Ablation",
        "",
        f"`bench/ablation.sh {a.seconds:g} {a.seeds}` on {date} at {commit}: each guided decision "
        "alone and each removed from full guiding, at equal time (training included), every "
        f"method once per seed ({a.seeds} seeds), against the scene's reference. `/ full` is the "
        "ratio of the method's median to full guiding's. Scenes: "
        f"{', '.join(scenes)}; a bench scene without a table here has not been ablated yet.",
        "",
    ]
    for name in scenes:
        results = tables.load_json(pathlib.Path(a.out) / name / "ablation" / "results.json")
        if not results:
            continue
        title = f"{name} (held out)" if name in held_out else name
        lines += scene_table(title, results) + [""]
    section = "\n".join(lines).rstrip("\n") + "\n"
    print(section)
    tables.write_section(a.results, "Ablation", section)


if __name__ == "__main__":
    main()
