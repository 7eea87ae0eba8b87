#!/usr/bin/env bash
# Fuzzes every parser of ours with libFuzzer (cargo-fuzz, nightly only here;
# the project builds on stable). Usage:
#
#   fuzz/run.sh [--minutes N] [--jobs J] [--fork F] [--bin PATH] [--seed-only] [TARGET...]
#
# Builds the `all` binary (every target, picked by AMC_FUZZ_TARGET), seeds
# fuzz/corpus/TARGET from fuzz/seeds and from real files in ../shared/data
# (cut down with ffmpeg), then runs each TARGET (all by default) for N minutes
# of wall time (default 10), J targets at a time (default: the cores), each
# with F libFuzzer processes (-fork, default 1). --bin runs a prebuilt `all`
# (e.g. copied to a machine without Rust, after --seed-only here).
# Crashes land in fuzz/artifacts/TARGET/ (fuzzing goes on after one); copy
# each into fuzz/regressions/TARGET/ with the fix, and `cargo test --release
# -p amc-e2e --test fuzz_regressions` replays them on stable from then on.
#
# Limits per target (what "no allocation beyond the documented limits"
# means here) are in LIMITS below; -timeout 10 s catches hangs.
set -euo pipefail
cd "$(dirname "$0")"

minutes=10
jobs=$(nproc)
fork=1
bin=""
seed_only=0
targets=()
while [ $# -gt 0 ]; do
  case "$1" in
    --minutes) minutes="$2"; shift 2 ;;
    --jobs) jobs="$2"; shift 2 ;;
    --fork) fork="$2"; shift 2 ;;
    --bin) bin="$2"; shift 2 ;;
    --seed-only) seed_only=1; shift ;;
    -h|--help) sed -n '2,19p' "$0"; exit 0 ;;
    *) targets+=("$1"); shift ;;
  esac
done
all=(y4m lens params_json params_query multipart ingest_frame wasm_args)
[ ${#targets[@]} -gt 0 ] || targets=("${all[@]}")

# TARGET: max input bytes, malloc limit (MB), RSS limit (MB).
declare -A LIMITS=(
  [y4m]="65536 256 1024"
  [lens]="16384 256 1024"
  [params_json]="4096 512 1024"
  [params_query]="4096 512 1024"
  [multipart]="65536 256 1024"
  [ingest_frame]="65536 512 1024"
  [wasm_args]="4096 2600 4096"
)

data=../../shared/data
[ -d "$data" ] || data=../shared/data

seed() {
  local t=$1 dir=corpus/$1
  mkdir -p "$dir"
  [ -d "seeds/$t" ] && cp -n seeds/"$t"/* "$dir"/ 2>/dev/null || true
  case "$t" in
    y4m)
      # Small clips of real footage in every layout the reader takes.
      for spec in "yuv420p:" "yuv422p:" "yuv444p:" "gray:" "yuvj420p:-color_range pc"; do
        pix=${spec%%:*}; extra=${spec#*:}
        out="$dir/karma-$pix.y4m"
        [ -f "$out" ] || ffmpeg -v error -y -i "$data/karma/karma.mp4" -frames:v 3 \
          -vf scale=32:18 -pix_fmt "$pix" $extra -strict -1 "$out" || true
      done
      [ -f "$dir/cup-odd.y4m" ] || ffmpeg -v error -y -i "$data/cup/cup.mp4" -frames:v 2 \
        -vf scale=33:17 -pix_fmt yuv420p "$dir/cup-odd.y4m" || true
      ;;
    ingest_frame)
      # JPEGs as publishers send them: baseline, progressive, grey, odd sizes.
      [ -f "$dir/cc9.jpg" ] || ffmpeg -v error -y -i "$data/cc9/frames/RE_frame-99.jpg" \
        -vf scale=64:36 "$dir/cc9.jpg" || true
      [ -f "$dir/pano-grey.jpg" ] || ffmpeg -v error -y -i "$data/pano/pannellum_examplepano.jpg" \
        -vf scale=96:48,format=gray "$dir/pano-grey.jpg" || true
      [ -f "$dir/karma-odd.jpg" ] || ffmpeg -v error -y -i "$data/karma/karma.mp4" -frames:v 1 \
        -vf scale=31:17 -q:v 8 "$dir/karma-odd.jpg" || true
      ;;
  esac
}

for t in "${targets[@]}"; do seed "$t"; done
[ "$seed_only" = 1 ] && exit 0

if [ -z "$bin" ]; then
  command -v cargo-fuzz >/dev/null || cargo +nightly install cargo-fuzz --locked
  rustup toolchain list | grep -q '^nightly' || rustup toolchain install nightly --profile minimal
  # Debug assertions on (-a): an overflow is a finding too.
  cargo +nightly fuzz build -a all
  bin=${CARGO_TARGET_DIR:-target}/x86_64-unknown-linux-gnu/release/all
fi

run_one() {
  local t=$1
  read -r max_len malloc rss <<<"${LIMITS[$t]}"
  mkdir -p "artifacts/$t" "logs"
  local rc=0
  AMC_FUZZ_TARGET=$t "$bin" "corpus/$t" -max_total_time="$(awk "BEGIN{print int($minutes*60)}")" \
    -timeout=10 -max_len="$max_len" -malloc_limit_mb="$malloc" -rss_limit_mb="$rss" \
    -fork="$fork" -ignore_crashes=1 -ignore_ooms=1 -ignore_timeouts=1 \
    -artifact_prefix="artifacts/$t/" -print_final_stats=1 > "logs/$t.log" 2>&1 || rc=$?
  echo "$t: exit $rc, $(grep -Eo 'Done [0-9]+ runs in [0-9]+ second|#[0-9]+: cov: [0-9]+ ft: [0-9]+ corp: [0-9]+' "logs/$t.log" | tail -1)"
  return $rc
}

failed=0
running=0
for t in "${targets[@]}"; do
  run_one "$t" &
  running=$((running + 1))
  if [ "$running" -ge "$jobs" ]; then wait -n || failed=1; running=$((running - 1)); fi
done
while [ "$running" -gt 0 ]; do wait -n || failed=1; running=$((running - 1)); done
# The targets' scratch folders (one per fuzzing process).
rm -rf /dev/shm/amc-fuzz-* "${TMPDIR:-/tmp}"/amc-fuzz-* 2>/dev/null || true
found=$(find artifacts -type f 2>/dev/null | sort)
if [ -n "$found" ]; then
  echo "findings (crash, leak, OOM or timeout inputs):"
  echo "$found"
  failed=1
else
  echo "no findings"
fi
exit $failed
