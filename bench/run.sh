#!/usr/bin/env bash
# The benchmark suite: guided against unguided at equal time on every scene of scenes/bench/.
# Usage: bench/run.sh [SECONDS_PER_METHOD] [REFERENCE_SECONDS]   (defaults 20 and 120)
# Writes bench/out/<scene>/ (tables, images), bench/RESULTS.md (a summary, every table, the
# machine, the date) and bench/plots/ (each scene's convergence plot and image strip, which
# RESULTS.md shows). References are kept between runs; delete bench/out to redo them.
set -euo pipefail
cd "$(dirname "$0")/.."
budget=${1:-20}
ref_time=${2:-120}
cargo build --release --quiet --bin zerovar
bin=target/release/zerovar
results=bench/RESULTS.md
{
  echo "# Benchmark results"
  echo
  echo "Equal time: ${budget} s per method (a guided method's training included), relMSE against"
  echo "an unguided reference of ${ref_time} s; \`bench/run.sh ${budget} ${ref_time}\`."
  echo
  echo "- date: $(date -u +%Y-%m-%d)"
  echo "- machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
  echo "- zerovar: $(git rev-parse --short HEAD)"
} > "$results"
mkdir -p bench/plots
details=$(mktemp)
for scene in scenes/bench/*.toml; do
  name=$(basename "$scene" .toml)
  out=bench/out/$name
  mkdir -p "$out"
  if [ ! -f "$out/reference.exr" ]; then
    echo "$name: reference (${ref_time} s)" >&2
    $bin reference "$scene" -o "$out/reference.exr" --time "$ref_time" --quiet
  fi
  echo "$name: compare (${budget} s per method)" >&2
  $bin compare "$scene" --reference "$out/reference.exr" --time "$budget" --out "$out" --trim 0.0001 >/dev/null
  cp "$out/convergence.svg" "bench/plots/$name-convergence.svg"
  cp "$out/strip.png" "bench/plots/$name-strip.png"
  {
    echo; echo "## $name"; echo; cat "$out/results.md"; echo
    echo "![convergence](plots/$name-convergence.svg)"; echo
    echo "Reference, then each method in table order:"; echo
    echo "![images](plots/$name-strip.png)"
  } >> "$details"
done
# The headline: each scene's final checkpoint, the first method against the others.
python3 - "$results" bench/out scenes/bench <<'PY'
import json, pathlib, sys
results, out, scenes = sys.argv[1], pathlib.Path(sys.argv[2]), pathlib.Path(sys.argv[3])
rows = []
for scene in sorted(scenes.glob("*.toml")):
    methods = json.loads((out / scene.stem / "results.json").read_text())
    base = methods[0]["checkpoints"][-1]["error"]["rel_mse"]["all"]
    for m in methods[1:]:
        e = m["checkpoints"][-1]["error"]["rel_mse"]["all"]
        rows.append(f"| {scene.stem} | {base:.3e} | {m['name']} | {e:.3e} | {base / e:.2f} | {m['speedup']:.2f} |")
head = ["", "## Summary", "",
        "Equal-time relMSE of each method against the first (unguided); error ratio > 1 means",
        "the method wins. Speed-up is the efficiency ratio 1 / (relMSE x seconds).", "",
        "| scene | unguided relMSE | method | its relMSE | error ratio | speed-up |",
        "|---|---|---|---|---|---|"]
with open(results, "a") as f:
    f.write("\n".join(head + rows) + "\n")
PY
cat "$details" >> "$results"
rm -f "$details"
echo "wrote $results" >&2
