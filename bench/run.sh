#!/usr/bin/env bash
# The benchmark suite: zerovar's default methods (unguided, guided, auto) at equal time on every
# scene of scenes/bench/, each method rendered once per seed, and Mitsuba 3's volpath (and on
# chromatic scenes volpathmis) on the scene's XML twin, scenes/bench/<scene>.xml, at the same time
# with as many seeds.
# Usage: bench/run.sh [SECONDS_PER_METHOD] [REFERENCE_SECONDS] [SEEDS]   (defaults 30, 900, 3)
# The scenes are every scenes/bench/*.toml and every scenes/bench/*.xml with no .toml of the same
# name (an XML-only scene, which zerovar renders from the XML). bench/held-out.txt names the
# held-out set, reported apart and never tuned on (bench/README.md).
# Writes bench/out/<scene>/ (results.json, every Mitsuba run's JSON and log, images),
# bench/RESULTS.md (the machine, the date, the commit, the summary and every scene's table) and
# bench/plots/ (each scene's convergence plot, image strip and crops, which RESULTS.md shows).
# References are kept between runs while the scene file is unchanged (its SHA-256 is kept
# beside the reference); delete bench/out to redo them all. The reference's own noise is
# reported and taken out of the ratios where every run resolves it (see `zerovar compare`).
# The Mitsuba column needs `import mitsuba`: the script pip-installs it if it can, and
# libllvm19 for the LLVM variant; without them the column is left out or marked, and
# RESULTS.md says why.
set -euo pipefail
cd "$(dirname "$0")/.."
budget=${1:-30}
ref_time=${2:-900}
seeds=${3:-3}
case $seeds in
  '' | *[!0-9]* | 0) echo "SEEDS: give a positive whole number of renders per method, not '$seeds'" >&2; exit 2 ;;
esac
# Scenes whose media are chromatic (a name containing "chromatic" counts too): there Mitsuba's
# volpath samples distances with one channel's coefficient only, and volpathmis (spectral MIS)
# is the fair Mitsuba to compare with, so both run.
CHROMATIC="chromatic-slab"
# The trimmed relMSE leaves out the worst 0.1% of pixels: enough to show whether a few fireflies
# decide a ratio, too few to hide a real difference.
trim=0.001
held_out=bench/held-out.txt
results=bench/RESULTS.md
threads=$(nproc)
seeds_text="$seeds seeds"
if [ "$seeds" = 1 ]; then
  seeds_text="1 seed"
fi

cargo build --release --quiet --bin zerovar
bin=target/release/zerovar

# Setup: what was installed or skipped goes to RESULTS.md's header, so that a missing or
# slower Mitsuba is explained where its figures are.
setup=()
# tools/mitsuba-bench.py needs numpy, and OpenEXR to read the reference's standard-error layer
# (without it the agreement check is skipped).
if ! python3 -c 'import mitsuba, numpy, OpenEXR' 2>/dev/null; then
  echo "installing Mitsuba 3 (pip install mitsuba numpy OpenEXR)" >&2
  # python3 -m pip: the same Python that runs tools/mitsuba-bench.py.
  if python3 -m pip install --quiet mitsuba numpy OpenEXR >&2; then
    setup+=("pip installed mitsuba, numpy and OpenEXR")
  else
    setup+=("\`pip install mitsuba numpy OpenEXR\` failed")
  fi
fi
if mitsuba_version=$(python3 -c 'import mitsuba, numpy; print(mitsuba.__version__)' 2>/dev/null); then
  mitsuba=1
else
  mitsuba=0
fi
if [ "$mitsuba" = 1 ]; then
  # Mitsuba's LLVM variant (llvm_ad_rgb) needs a shared libLLVM that compiles its kernels (LLVM
  # 14 and 15 abort on those of Mitsuba 3.9; 19 works). Without one tools/mitsuba-bench.py falls
  # back to scalar_rgb, several times slower: not Mitsuba at its speed.
  if command -v dpkg >/dev/null; then
    if ! dpkg -L libllvm19 >/dev/null 2>&1; then
      if [ "$(id -u)" = 0 ]; then
        echo "installing libllvm19 (apt-get)" >&2
        # A fresh machine may have no package lists yet: update once and retry.
        if DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >&2 \
          || { apt-get update -qq >&2 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >&2; }; then
          setup+=("apt-get installed libllvm19")
        else
          setup+=("\`apt-get install libllvm19\` failed")
        fi
      else
        setup+=("libllvm19 is not installed and installing it needs root: skipped")
      fi
    fi
    if [ -z "${DRJIT_LIBLLVM_PATH:-}" ]; then
      lib=$(dpkg -L libllvm19 2>/dev/null | grep '/libLLVM\.so\.19\.1$' | head -n 1 || true)
      if [ -n "$lib" ]; then
        export DRJIT_LIBLLVM_PATH=$lib
      fi
    fi
  else
    setup+=("no dpkg: libllvm19 not looked for")
  fi
fi

scenes=()
for f in scenes/bench/*.toml scenes/bench/*.xml; do
  [ -e "$f" ] || continue
  # An XML beside a TOML of the same name is that scene's Mitsuba twin, not a scene of its own.
  if [[ $f == *.xml && -e ${f%.xml}.toml ]]; then
    continue
  fi
  scenes+=("$f")
done
if [ "${#scenes[@]}" = 0 ]; then
  echo "no scenes in scenes/bench" >&2
  exit 1
fi
mapfile -t scenes < <(printf '%s\n' "${scenes[@]}" | sort)

is_chromatic() {
  [[ $1 == *chromatic* || " $CHROMATIC " == *" $1 "* ]]
}
is_held_out() {
  # A loop, not grep in a pipe: with pipefail an early exit of grep -q can fail the pipe.
  local line
  [ -f "$held_out" ] || return 1
  while IFS= read -r line || [ -n "$line" ]; do
    if [[ $line =~ ^[[:space:]]*([^#[:space:]][^[:space:]]*)[[:space:]]*$ ]] && [ "${BASH_REMATCH[1]}" = "$1" ]; then
      return 0
    fi
  done < "$held_out"
  return 1
}

# The time it will take, so that nobody starts a two-hour run by accident: 3 methods x (seeds +
# the 1/8, 1/4 and 1/2 convergence renders) per scene, Mitsuba's runs, and new references.
runs=0
refs=0
for scene in "${scenes[@]}"; do
  name=$(basename "${scene%.*}")
  m=1
  if is_chromatic "$name"; then m=2; fi
  [ "$mitsuba" = 1 ] && [ -f "scenes/bench/$name.xml" ] || m=0
  runs=$((runs + m * seeds))
  out=bench/out/$name
  if [ ! -f "$out/reference.exr" ] || [ "$(cat "$out/reference.sha256" 2>/dev/null)" != "$(sha256sum "$scene" | cut -d' ' -f1)" ]; then
    refs=$((refs + 1))
  fi
done
awk -v n="${#scenes[@]}" -v s="$seeds" -v b="$budget" -v r="$runs" -v f="$refs" -v t="$ref_time" \
  'BEGIN { printf "%d scenes, %d Mitsuba runs, %d new references: about %.0f minutes\n", n, r, f,
           (n * 3 * (s + 0.875) * b + r * b + f * t) / 60 }' >&2

mkdir -p bench/plots
details=$(mktemp)
summary=$(mktemp)
trap 'rm -f "$details" "$summary"' EXIT
jsons=()  # every Mitsuba result of this run, for the variants in the header
for scene in "${scenes[@]}"; do
  name=$(basename "${scene%.*}")
  out=bench/out/$name
  xml=scenes/bench/$name.xml
  mkdir -p "$out"
  sum=$(sha256sum "$scene" | cut -d' ' -f1)
  if [ ! -f "$out/reference.exr" ] || [ "$(cat "$out/reference.sha256" 2>/dev/null)" != "$sum" ]; then
    echo "$name: reference (${ref_time} s)" >&2
    rm -f "$out/reference.sha256"
    $bin reference "$scene" -o "$out/reference.exr" --time "$ref_time" --quiet 2> "$out/reference.txt"
    echo "$sum" > "$out/reference.sha256"
  fi
  echo "$name: compare (${budget} s per method, ${seeds_text})" >&2
  $bin compare "$scene" --reference "$out/reference.exr" --time "$budget" --seeds "$seeds" \
    --trim "$trim" --out "$out" > /dev/null
  cp "$out/convergence.svg" "bench/plots/$name-convergence.svg"
  cp "$out/strip.png" "bench/plots/$name-strip.png"
  cp "$out/crops.png" "bench/plots/$name-crops.png"
  # A former run's Mitsuba results (other seeds, the old single mitsuba.json) would pass for
  # this run's.
  rm -f "$out"/mitsuba*.json "$out"/mitsuba*.log "$out"/mitsuba*.exr
  if [ "$mitsuba" = 1 ]; then
    if [ -f "$xml" ]; then
      integrators=(volpath)
      if is_chromatic "$name"; then
        integrators+=(volpathmis)
      fi
      for integrator in "${integrators[@]}"; do
        # volpath is every twin's default integrator; the others are set through $integrator.
        args=()
        if [ "$integrator" != volpath ]; then
          args=(--integrator "$integrator")
        fi
        for ((s = 0; s < seeds; s++)); do
          tag=mitsuba-$integrator-$s
          echo "$name: Mitsuba 3 $integrator, seed $s (${budget} s)" >&2
          # A failure is noted in the tables (from the log), not fatal: zerovar's figures stand
          # without Mitsuba's.
          if python3 tools/mitsuba-bench.py "$xml" --reference "$out/reference.exr" \
            --seconds "$budget" --threads "$threads" --seed "$s" --trim "$trim" --block 4 \
            ${args[@]+"${args[@]}"} --out "$out/$tag.exr" --json "$out/$tag.json" \
            > "$out/$tag.log" 2>&1; then
            jsons+=("$out/$tag.json")
          else
            rm -f "$out/$tag.json"
            echo "$name: Mitsuba 3 $integrator seed $s failed, see $out/$tag.log" >&2
          fi
        done
      done
    else
      echo "no $xml: $name has no Mitsuba 3 twin" > "$out/mitsuba-volpath-0.log"
    fi
  fi
  {
    if is_held_out "$name"; then
      echo; echo "## $name (held out)"; echo
    else
      echo; echo "## $name"; echo
    fi
    if [ -f "$out/reference.txt" ]; then
      echo "Unguided $(sed 's|-> .*||' "$out/reference.txt")(\`zerovar reference\`, its own seed)."; echo
    fi
    if [ "$mitsuba" = 1 ]; then
      python3 bench/tables.py scene "$out" "$xml" --trim "$trim"
    else
      python3 bench/tables.py scene "$out" "$xml" --trim "$trim" --no-mitsuba
    fi
    echo
    echo "![convergence](plots/$name-convergence.svg)"; echo
    echo "Reference, then each method in table order (the first seed):"; echo
    echo "![images](plots/$name-strip.png)"; echo
    echo "Magnified where unguided has the most error (same order):"; echo
    echo "![crops](plots/$name-crops.png)"
  } >> "$details"
done
# The headline: per scene the first method (unguided) against the others and against Mitsuba
# 3, the tuning set and the held-out set apart.
python3 bench/tables.py summary bench/out scenes/bench "$mitsuba" --held-out "$held_out" \
  --trim "$trim" > "$summary"

# Sections other scripts write (bench/unbiased.sh's "Unbiasedness", the "Ablation") are kept.
kept=$(mktemp)
trap 'rm -f "$details" "$summary" "$kept"' EXIT
if [ -f "$results" ]; then
  awk '/^## (Unbiasedness|Ablation)$/ { keep = 1 } /^## / && !/^## (Unbiasedness|Ablation)$/ { keep = 0 }
       keep' "$results" > "$kept"
fi

# The header last: which Mitsuba variants ran is known only now.
dirty=""
if ! git diff --quiet HEAD -- 2> /dev/null; then
  dirty=" with uncommitted changes"
fi
{
  echo "# Benchmark results"
  echo
  echo "Equal time: ${budget} s per method and seed (a guided method's training included), ${seeds_text} per"
  echo "method; relMSE against an unguided reference (${ref_time} s for a new one; each scene's section gives"
  echo "its spp and seconds), its own noise taken out where every run resolves it. Scenes in"
  echo "\`${held_out}\` are the held-out set, reported apart and never tuned on (bench/README.md)."
  echo
  echo "- date: $(date -u +%Y-%m-%d)"
  echo "- machine: ${threads} cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
  echo "- zerovar: $(git rev-parse --short HEAD)${dirty}"
  echo "- command: \`bench/run.sh ${budget} ${ref_time} ${seeds}\`"
  if [ "$mitsuba" = 1 ]; then
    variants=$(python3 -c '
import collections, json, sys
c = collections.Counter(json.load(open(p))["variant"] for p in sys.argv[1:])
v = ", ".join("%s (%d run%s)" % (k, n, "" if n == 1 else "s") for k, n in sorted(c.items()))
if any(not k.startswith("llvm") for k in c):
    v += "; a scene with a scalar_rgb run has its Mitsuba figure marked as the fallback, not compared"
print(v or "none: every run failed (see each scene)")' ${jsons[@]+"${jsons[@]}"}) \
      || variants="unknown (a result could not be read)"
    echo "- Mitsuba 3: ${mitsuba_version} (\`tools/mitsuba-bench.py\`, volpath and on chromatic scenes"
    echo "  volpathmis, ${seeds_text}, ${threads} threads, the same budget including scene load and JIT)"
    echo "- Mitsuba 3 variant: ${variants}"
    echo "- libLLVM: ${DRJIT_LIBLLVM_PATH:-DRJIT_LIBLLVM_PATH unset (tools/mitsuba-bench.py picks the newest libLLVM it finds)}"
  else
    echo "- Mitsuba 3: skipped, \`python3 -c 'import mitsuba, numpy'\` failed (\`pip install mitsuba numpy OpenEXR\` adds the Mitsuba columns)"
  fi
  for note in ${setup[@]+"${setup[@]}"}; do
    echo "- setup: $note"
  done
  cat "$summary"
  cat "$details"
  if [ -s "$kept" ]; then
    echo
    cat "$kept"
  fi
} > "$results"
echo "wrote $results" >&2
