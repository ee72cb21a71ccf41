# Sourced by run-kotlin.sh and run-swift.sh: replays the recordings their tests made with the
# build's monotrack ($MONOTRACK) from $RECORDINGS and counts each file in $passed / $failed.
# A file passes when every frame replays identical, and it has at least one frame.
replay_recordings() {
  local name replay_rc identical
  for name in "$@"; do
    set +e
    "$MONOTRACK" replay "$RECORDINGS/$name.mtrec" --out "$RECORDINGS/$name.jsonl" \
      > "$RECORDINGS/$name.log" 2>&1
    replay_rc=$?
    set -e
    identical=$(grep -E '^monotrack: [0-9]+ of [0-9]+ frames identical' "$RECORDINGS/$name.log" | tail -1 || true)
    echo "$name.mtrec: ${identical#monotrack: }"
    if [ "$replay_rc" -eq 0 ] && [[ "$identical" =~ ^monotrack:\ ([1-9][0-9]*)\ of\ ([0-9]+)\ frames ]] &&
       [ "${BASH_REMATCH[1]}" = "${BASH_REMATCH[2]}" ]; then
      passed=$((passed + 1))
    else
      cat "$RECORDINGS/$name.log"; failed=$((failed + 1))
    fi
  done
}
