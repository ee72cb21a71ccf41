#!/usr/bin/env bash
# Coverage-guided fuzzing (cargo-fuzz, libFuzzer, AddressSanitizer) of what the SDK takes from apps.
# Usage: fuzz/run.sh [SECONDS_PER_TARGET=600] [TARGET...]
# Needs the nightly toolchain and cargo-fuzz: installed here when missing. Each target starts from
# its committed corpus (fuzz/corpus/<target>/, minimised) plus generated seeds (model_bundle: the
# built-in bundle, make_bundle.py; frames: a few valid frames; recording: the corpus is written by
# make_recording_corpus.py from the format's document); new inputs go to a scratch copy, and a crash
# stops the run with the input under fuzz/artifacts/<target>/. Prints one line per target:
# executions, seconds, corpus size, crashes.
set -euo pipefail
cd "$(dirname "$0")"
SECS=${1:-600}
shift || true
TARGETS=("$@")
[ ${#TARGETS[@]} -eq 0 ] && TARGETS=(frames json_inputs fit_inputs model_bundle recording)
# Missing tools are installed; where that cannot be done (no network to the registries), the run
# is skipped with a line rather than failed: nothing about the SDK was tested or found wrong.
skip() { echo "SKIPPED: fuzzing ($1)"; exit 0; }
rustup toolchain list | grep -q '^nightly' || rustup toolchain install nightly --profile minimal ||
  skip "the nightly toolchain could not be installed"
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --locked ||
  skip "cargo-fuzz could not be installed"
WORK=${FUZZ_WORK:-$(pwd)/../target/fuzz-work}
mkdir -p "$WORK"
# Every target at once (cargo-fuzz builds one or all).
cargo +nightly fuzz build -O
for t in "${TARGETS[@]}"; do
  scratch="$WORK/$t"; rm -rf "$scratch"; mkdir -p "$scratch"
  [ -d "corpus/$t" ] && cp -r "corpus/$t/." "$scratch/"
  case $t in
    model_bundle)
      python3 ../core/models/train/make_bundle.py "$scratch/seed-builtin" > /dev/null ;;
    json_inputs)
      { printf '\x02'; cat ../core/models/face_model/face_model.json; } > "$scratch/seed-face-model"
      { printf '\x03'; cat ../core/models/body/pose_prior.json; } > "$scratch/seed-pose-prior"
      { printf '\x04'; cat ../core/models/m3/m3.json; } > "$scratch/seed-m3" ;;
  esac
  log="$WORK/$t.log"
  set +e
  cargo +nightly fuzz run -O "$t" "$scratch" -- -max_total_time="$SECS" -rss_limit_mb=4096 \
    -max_len=1048576 -print_final_stats=1 > "$log" 2>&1
  rc=$?
  set -e
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  crashes=$(ls "artifacts/$t" 2>/dev/null | wc -l)
  echo "fuzz $t: ${execs:-0} executions in ${SECS} s, corpus $(ls "$scratch" | wc -l) inputs, exit $rc, artifacts $crashes"
  [ "$rc" -eq 0 ] || { tail -30 "$log"; exit 1; }
done
