#!/usr/bin/env bash
# The benchmark suite: guided against unguided at equal time on every scene of scenes/bench/,
# and Mitsuba 3's volpath on the same scene (scenes/bench/<scene>.xml) at the same time.
# Usage: bench/run.sh [SECONDS_PER_METHOD] [REFERENCE_SECONDS]   (defaults 20 and 600)
# Writes bench/out/<scene>/ (tables, images), bench/RESULTS.md (a summary, every table, the
# machine, the date) and bench/plots/ (each scene's convergence plot, image strip and crops, which
# RESULTS.md shows). References are kept between runs while the scene file is unchanged (its
# SHA-256 is kept beside the reference); delete bench/out to redo them all. The reference's
# own noise is reported and taken out of the ratios (see `zerovar compare` in README).
# The Mitsuba 3 column needs `import mitsuba` to work (pip install mitsuba); without it the
# column is left out and RESULTS.md says why. tools/mitsuba-bench.py picks the variant.
set -euo pipefail
cd "$(dirname "$0")/.."
budget=${1:-20}
ref_time=${2:-600}
cargo build --release --quiet --bin zerovar
bin=target/release/zerovar
results=bench/RESULTS.md
{
  echo "# Benchmark results"
  echo
  echo "Equal time: ${budget} s per method (a guided method's training included), relMSE against"
  echo "an unguided reference (${ref_time} s for a new one; each scene's section gives its spp and seconds), its own noise taken out; \`bench/run.sh ${budget} ${ref_time}\`."
  echo
  echo "- date: $(date -u +%Y-%m-%d)"
  echo "- machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
  echo "- zerovar: $(git rev-parse --short HEAD)"
} > "$results"
mkdir -p bench/plots
details=$(mktemp)
threads=$(nproc)
if mitsuba_version=$(python3 -c 'import mitsuba; print(mitsuba.__version__)' 2>/dev/null); then
  mitsuba=1
  echo "- Mitsuba 3: ${mitsuba_version} (\`tools/mitsuba-bench.py\`, volpath, ${threads} threads, the same budget including scene load and JIT)" >> "$results"
else
  mitsuba=0
  echo "- Mitsuba 3: skipped, \`python3 -c 'import mitsuba'\` failed (\`pip install mitsuba\` adds the Mitsuba column)" >> "$results"
fi
for scene in scenes/bench/*.toml; do
  name=$(basename "$scene" .toml)
  out=bench/out/$name
  mkdir -p "$out"
  sum=$(sha256sum "$scene" | cut -d' ' -f1)
  if [ ! -f "$out/reference.exr" ] || [ "$(cat "$out/reference.sha256" 2>/dev/null)" != "$sum" ]; then
    echo "$name: reference (${ref_time} s)" >&2
    rm -f "$out/reference.sha256"
    $bin reference "$scene" -o "$out/reference.exr" --time "$ref_time" --quiet 2> "$out/reference.txt"
    echo "$sum" > "$out/reference.sha256"
  fi
  echo "$name: compare (${budget} s per method)" >&2
  $bin compare "$scene" --reference "$out/reference.exr" --time "$budget" --out "$out" --trim 0.0001 >/dev/null
  cp "$out/convergence.svg" "bench/plots/$name-convergence.svg"
  cp "$out/strip.png" "bench/plots/$name-strip.png"
  cp "$out/crops.png" "bench/plots/$name-crops.png"
  rm -f "$out/mitsuba.json" "$out/mitsuba.log"
  xml=scenes/bench/$name.xml
  if [ "$mitsuba" = 1 ]; then
    if [ -f "$xml" ]; then
      echo "$name: Mitsuba 3 (${budget} s)" >&2
      python3 tools/mitsuba-bench.py "$xml" --reference "$out/reference.exr" --seconds "$budget" \
        --threads "$threads" --trim 0.0001 --block 4 --out "$out/mitsuba.exr" \
        --json "$out/mitsuba.json" > "$out/mitsuba.log" 2>&1 \
        || { rm -f "$out/mitsuba.json"; echo "$name: Mitsuba 3 failed, see $out/mitsuba.log" >&2; }
    else
      echo "no $xml: $name has no Mitsuba 3 version" > "$out/mitsuba.log"
    fi
  fi
  {
    echo; echo "## $name"; echo
    if [ -f "$out/reference.txt" ]; then
      echo "Unguided $(sed 's|-> .*||' "$out/reference.txt")(\`zerovar reference\`, its own seed)."; echo
    fi
    if [ "$mitsuba" = 1 ]; then
      python3 bench/tables.py scene "$out" "$xml"
    else
      cat "$out/results.md"
    fi
    echo
    echo "![convergence](plots/$name-convergence.svg)"; echo
    echo "Reference, then each method in table order:"; echo
    echo "![images](plots/$name-strip.png)"; echo
    echo "Magnified where unguided has the most error (same order):"; echo
    echo "![crops](plots/$name-crops.png)"
  } >> "$details"
done
# The headline: each scene's final checkpoint, the first method against the others (and
# against Mitsuba 3 when it ran).
python3 bench/tables.py summary "$results" bench/out scenes/bench "$mitsuba"
cat "$details" >> "$results"
rm -f "$details"
echo "wrote $results" >&2
