#!/usr/bin/env bash
# The ablation of guiding's decisions: on each scene, full guiding, each guided decision alone,
# each removed from full guiding, full guiding with the zero-variance collision density
# (distance alpha 0.5) and unguided sampling, at equal time, once per seed (`zerovar compare
# --no-curve`). Not part of CI: about SECONDS x SEEDS x 9 per scene (13.5 min at the defaults).
# Usage: bench/ablation.sh [SECONDS] [SEEDS] [SCENES] [REFERENCE_SECONDS]
#        (defaults 30, 3, every bench scene, 180; SCENES comma-separated names of scenes/bench)
#        ZEROVAR=path runs that binary instead of building target/release/zerovar, and
#        COMMIT names the commit it was built from in the table (default HEAD).
# References are bench/run.sh's (bench/out/<scene>/reference.exr) where they exist, else rendered
# for REFERENCE_SECONDS into the same place. Writes bench/out/<scene>/ablation/ and the section
# "Ablation" of bench/RESULTS.md (every scene with an ablation in bench/out), and prints it.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-30}
seeds=${2:-3}
scenes=${3:-}
ref_time=${4:-180}
bin=${ZEROVAR:-}
if [ -z "$bin" ]; then
  cargo build --release --quiet --bin zerovar
  bin=target/release/zerovar
fi
if [ -z "$scenes" ]; then
  scenes=$(ls scenes/bench | sed -n 's/\.\(toml\|xml\)$//p' | sort -u | paste -sd, -)
fi
methods=(
  unguided=guiding:off
  full=guiding:full
  directions=guiding:directions
  distances=guiding:distances
  rr=guiding:rr
  no-directions=guiding:distances+rr
  no-distances=guiding:directions+rr
  no-rr=guiding:directions+distances
  full-density=guiding:full,distance-alpha:0.5
)
args=()
for m in "${methods[@]}"; do
  args+=(--method "$m")
done
IFS=, read -ra names <<< "$scenes"
for name in "${names[@]}"; do
  scene=scenes/bench/$name.toml
  [ -f "$scene" ] || scene=scenes/bench/$name.xml
  [ -f "$scene" ] || { echo "no scene scenes/bench/$name.toml or .xml" >&2; exit 2; }
  out=bench/out/$name
  mkdir -p "$out"
  # bench/run.sh's reference while the scene file is unchanged (its SHA-256 beside it).
  sum=$(sha256sum "$scene" | cut -d' ' -f1)
  if [ ! -f "$out/reference.exr" ] || [ "$(cat "$out/reference.sha256" 2>/dev/null)" != "$sum" ]; then
    echo "$name: reference ($ref_time s)" >&2
    rm -f "$out/reference.sha256"
    "$bin" reference "$scene" -o "$out/reference.exr" --time "$ref_time" --quiet 2> "$out/reference.txt"
    echo "$sum" > "$out/reference.sha256"
  fi
  echo "$name: ablation, 9 methods x $seeds seeds x $seconds s" >&2
  "$bin" compare "$scene" --reference "$out/reference.exr" --time "$seconds" --seeds "$seeds" \
    --no-curve "${args[@]}" --out "$out/ablation" > "$out/ablation.log" 2>&1 \
    || { echo "$name: compare failed, see $out/ablation.log" >&2; exit 1; }
done
# Scenes run before keep their own tables (and dates); only those run now are rewritten.
python3 bench/ablation.py bench/out --results bench/RESULTS.md --seconds "$seconds" --seeds "$seeds" \
  --fresh "$(IFS=,; echo "${names[*]}")" ${COMMIT:+--commit "$COMMIT"}
