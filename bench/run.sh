#!/usr/bin/env bash
# The benchmark suite: guided against unguided at equal time on every scene of scenes/bench/.
# Usage: bench/run.sh [SECONDS_PER_METHOD] [REFERENCE_SECONDS]   (defaults 20 and 120)
# Writes bench/out/<scene>/ (tables, images) and bench/RESULTS.md (every table, the machine,
# the date). References are kept between runs; delete bench/out to redo them.
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
for scene in scenes/bench/*.toml; do
  name=$(basename "$scene" .toml)
  out=bench/out/$name
  mkdir -p "$out"
  [ -f "$out/reference.exr" ] || $bin reference "$scene" -o "$out/reference.exr" --time "$ref_time" --quiet
  $bin compare "$scene" --reference "$out/reference.exr" --time "$budget" --out "$out" --trim 0.0001 >/dev/null
  { echo; echo "## $name"; echo; cat "$out/results.md"; } >> "$results"
done
echo "wrote $results"
