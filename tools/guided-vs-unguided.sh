#!/usr/bin/env bash
# Equal-time error of guided against unguided rendering on the example scenes.
# Usage: tools/guided-vs-unguided.sh [SECONDS] [REFERENCE_SECONDS]   (defaults 20 and 120)
# Writes images to out/measure/ and prints a markdown table of relMSE against an unguided
# reference rendered with another seed for REFERENCE_SECONDS.
set -euo pipefail
cd "$(dirname "$0")/.."
budget=${1:-20}
ref_time=${2:-120}
train=$((budget / 4))
cargo build --release --quiet --bin zerovar --example relmse
bin=target/release/zerovar
relmse=target/release/examples/relmse
dir=out/measure
mkdir -p "$dir"
echo "| scene | unguided relMSE | guided (full) relMSE | ratio | guided training s |"
echo "|---|---|---|---|---|"
for s in fog-sphere cloud fog-room chromatic-box; do
  [ -f "$dir/$s-ref.exr" ] || $bin render "scenes/$s.toml" -o "$dir/$s-ref.exr" --time "$ref_time" --seed 1000 --quiet 2>/dev/null
  $bin render "scenes/$s.toml" -o "$dir/$s-off.exr" --time "$budget" --quiet 2>/dev/null
  $bin render "scenes/$s.toml" -o "$dir/$s-full.exr" --guiding full --train-time "$train" \
    --time $((budget - train)) --stats "$dir/$s-full.json" --quiet 2>/dev/null
  off=$($relmse "$dir/$s-ref.exr" "$dir/$s-off.exr" | awk '{print $3}')
  full=$($relmse "$dir/$s-ref.exr" "$dir/$s-full.exr" | awk '{print $3}')
  tsec=$(python3 -c "import json;print(round(json.load(open('$dir/$s-full.json'))['training']['seconds'],1))")
  ratio=$(python3 -c "print(round($off/$full,2))")
  echo "| $s | $off | $full | $ratio | $tsec |"
done
