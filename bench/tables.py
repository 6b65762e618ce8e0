#!/usr/bin/env python3
"""The tables of bench/RESULTS.md, for bench/run.sh.

    python3 bench/tables.py summary RESULTS.md OUT_DIR SCENES_DIR MITSUBA(0|1)
        appends the summary table (every scene's final checkpoints; with MITSUBA=1 also
        Mitsuba 3's equal-time relMSE and the error ratio Mitsuba / unguided zerovar).
    python3 bench/tables.py scene OUT_DIR/<scene> SCENE.xml
        prints one scene's table: `zerovar compare`'s table (results.json) with a row for
        Mitsuba 3 (mitsuba.json from tools/mitsuba-bench.py) and a column comparing each row
        with it, or a note saying why Mitsuba is missing (mitsuba.log).
"""

import json
import pathlib
import sys


def rust_e(x, digits=4):
    """A float as Rust's `{:.4e}` writes it (1.2486e-1, not Python's 1.2486e-01)."""
    mantissa, exponent = f"{x:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def load_mitsuba(out):
    path = out / "mitsuba.json"
    return json.loads(path.read_text()) if path.is_file() else None


def why_missing(out):
    log = out / "mitsuba.log"
    lines = [l for l in log.read_text().splitlines() if l.strip()] if log.is_file() else []
    return lines[-1] if lines else "tools/mitsuba-bench.py left no log"


def excess_basis(errors):
    """Whether every error (a metrics dict) has the reference's noise share and an excess that
    stands out of its standard error, as `zerovar compare` decides its `error_basis`."""
    def resolved(e):
        n = e.get("reference_noise")
        return n is not None and n["excess"]["all"] > 2.0 * n["excess_std_error"]
    return all(resolved(e) for e in errors)


def scored(e, excess):
    """The relMSE a ratio uses: less the reference's noise when `excess`."""
    return e["reference_noise"]["excess"]["all"] if excess else e["rel_mse"]["all"]


def summary(results, out, scenes, mitsuba):
    rows = []
    for scene in sorted(scenes.glob("*.toml")):
        methods = json.loads((out / scene.stem / "results.json").read_text())
        m3 = load_mitsuba(out / scene.stem) if mitsuba else None
        errors = [m["checkpoints"][-1]["error"] for m in methods] + ([m3["error"]] if m3 else [])
        excess = excess_basis(errors)
        first = errors[0]
        noise = first["reference_noise"]["share"]["all"] if first.get("reference_noise") else None
        base = scored(first, excess)
        extra = ""
        if mitsuba:
            if m3 is None:
                extra = " failed | - |"
            else:
                e3 = scored(m3["error"], excess)
                extra = f" {e3:.3e} | {e3 / base:.2f} |"
        lead = f"| {scene.stem} | {'-' if noise is None else f'{noise:.2e}'} | {'yes' if excess else 'no'} "
        for m in methods[1:]:
            e = scored(m["checkpoints"][-1]["error"], excess)
            rows.append(f"{lead}| {base:.3e} | {m['name']} | {e:.3e} | {base / e:.2f} "
                        f"| {m['speedup']:.2f} |{extra}")
    head = ["", "## Summary", "",
            "Equal-time relMSE of each method against the first (unguided); error ratio > 1 means",
            "the method wins. Speed-up is the efficiency ratio 1 / (relMSE x seconds).",
            "The reference is a finite render too: its own noise (reference noise, from its",
            "standard-error layer) adds to every relMSE and pulls every ratio towards 1. Where",
            "`less noise` says yes, each relMSE here is the excess over that noise (every method's",
            "excess more than twice its standard error over pixels); the scene tables give both."]
    if mitsuba:
        head += ["Mitsuba 3 is `volpath` on the scene's XML twin at the same wall-clock time (scene",
                 "load and JIT included) and thread count; Mitsuba / unguided is its relMSE over",
                 "zerovar's unguided relMSE (> 1: unguided zerovar has the smaller error). See each",
                 "scene's table for the variant, spp and how well the two renderers agree.", "",
                 "| scene | reference noise | less noise | unguided relMSE | method | its relMSE "
                 "| error ratio | speed-up | Mitsuba 3 relMSE | Mitsuba / unguided |",
                 "|---|---|---|---|---|---|---|---|---|---|"]
    else:
        head += ["", "| scene | reference noise | less noise | unguided relMSE | method | its relMSE "
                 "| error ratio | speed-up |", "|---|---|---|---|---|---|---|---|"]
    with open(results, "a") as f:
        f.write("\n".join(head + rows) + "\n")


def scene_table(out, xml):
    methods = json.loads((out / "results.json").read_text())
    m3 = load_mitsuba(out)
    base_eff = methods[0]["efficiency"]
    errors = [m["checkpoints"][-1]["error"] for m in methods] + ([m3["error"]] if m3 else [])
    excess = excess_basis(errors)
    noisy = all(e.get("reference_noise") for e in errors)
    cols = "| method | seconds | spp | relMSE |" + (" relMSE - reference noise |" if noisy else "")
    cols += " MSE | MAPE | SMAPE | efficiency | speed-up |"
    lines = []
    e3 = scored(m3["error"], excess) if m3 else None
    lines.append(cols + (" Mitsuba / this |" if m3 else ""))
    lines.append("|---" * (9 + noisy + (1 if m3 else 0)) + "|")

    def row(name, seconds, spp, e, efficiency, speedup):
        r = f"| {name} | {seconds:.2f} | {spp} | {rust_e(e['rel_mse']['all'])} | "
        if noisy:
            n = e["reference_noise"]
            r += f"{rust_e(n['excess']['all'])} ± {n['excess_std_error']:.1e} | "
        r += (f"{rust_e(e['mse']['all'])} | {e['mape']['all']:.4f} | {e['smape']['all']:.4f} | "
              f"{rust_e(efficiency)} | {speedup:.2f} |")
        if m3:
            r += f" {e3 / scored(e, excess):.2f} |"
        return r

    for m in methods:
        c = m["checkpoints"][-1]
        lines.append(row(m["name"], c["seconds"], c["spp"], c["error"], m["efficiency"], m["speedup"]))
    if m3:
        eff = 1.0 / max(e3 * m3["seconds"], 1e-300)
        lines.append(row(f"Mitsuba 3 ({m3['variant']})", m3["seconds"], m3["spp"], m3["error"], eff,
                         eff / base_eff))
    print("\n".join(lines))
    if noisy:
        share = errors[0]["reference_noise"]["share"]["all"]
        print()
        print(f"The reference's own noise adds {rust_e(share)} to every relMSE; efficiency, speed-up"
              + (" and Mitsuba / this use the relMSE less it." if excess else
                 " and Mitsuba / this use the raw relMSE (some excess is not resolved)."))
    if m3:
        print()
        note = (f"Mitsuba 3 {m3['mitsuba']} `{m3['variant']}` on `{xml}`, {m3['threads']} threads: "
                f"{m3['load_seconds']:.2f} s to load, {m3['first_pass_seconds']:.2f} s for the first "
                f"pass (JIT included), {m3['passes']} passes. Mitsuba / this is Mitsuba's relMSE "
                "over the row's (> 1: the row has the smaller error).")
        if m3.get("notes"):
            note += " Note: " + "; ".join(m3["notes"]) + "."
        g = m3.get("agreement")
        if g:
            q = ", ".join(f"{v:+.2f}" for v in g["quadrants"])
            note += (f" Agreement with the reference ({g['block']}x{g['block']}-pixel blocks): "
                     f"|z| > 3 in {100 * g['outliers']:.2f}% of block-channels (0.27% expected), "
                     f"pooled z {g['whole']:+.2f} (quadrants {q}).")
        print(note)
    else:
        print()
        print(f"Mitsuba 3: no result ({why_missing(out)}).")


def main(argv):
    if len(argv) == 6 and argv[1] == "summary":
        summary(argv[2], pathlib.Path(argv[3]), pathlib.Path(argv[4]), argv[5] == "1")
    elif len(argv) == 4 and argv[1] == "scene":
        scene_table(pathlib.Path(argv[2]), argv[3])
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv)
