#!/usr/bin/env bash
# The high-power agreement run: for every bench scene and every guiding mode, guided renders
# against unguided ones, until the relative standard error of the difference of their image
# means is at most TARGET (or the scene's seconds are spent). Not part of CI: about
# SCENE_SECONDS per scene (default 300 s, so about an hour for the bench).
# Usage: bench/unbiased.sh [TARGET] [SCENE_SECONDS] [SCENES]   (defaults 0.002, 300, all;
#        SCENES comma-separated names of scenes/bench files)
# Writes the section "Unbiasedness" of bench/RESULTS.md (bench/run.sh keeps it) and prints it.
set -euo pipefail
cd "$(dirname "$0")/.."
target=${1:-0.002}
seconds=${2:-300}
scenes=${3:-}
if ! python3 -c 'import numpy, OpenEXR' 2>/dev/null; then
  echo "installing numpy and OpenEXR (pip)" >&2
  python3 -m pip install --quiet numpy OpenEXR >&2
fi
cargo build --release --quiet --bin zerovar
args=(target/release/zerovar --target "$target" --scene-seconds "$seconds")
if [ -n "$scenes" ]; then
  args+=(--scenes "$scenes")
fi
python3 bench/unbiased.py "${args[@]}"
