#!/usr/bin/env bash
# The API against its own schema: starts `amc serve` on a loopback port and
# runs schemathesis (PyPI) over every operation of /openapi.json with every
# check (status codes, content types, problem+json bodies against their
# schemas, no 5xx, schema-valid options accepted, invalid ones refused).
#
#   bash tests/api_schema.sh              # CI: a bounded run (~2 min)
#   AMC_SCHEMA_SECS=1800 bash tests/api_schema.sh   # the long run
#
# Needs: a built release `amc` (cargo build --release) and `schemathesis`
# (`pip install schemathesis`). Exits non-zero on any failure; the report is
# in target/schemathesis/.
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${AMC_SCHEMA_SECS:-100}
amc=${AMC_BIN:-target/release/amc}
st=$(command -v schemathesis || command -v st || true)
[ -n "$st" ] || { echo "schemathesis is not installed: pip install schemathesis" >&2; exit 1; }
[ -x "$amc" ] || cargo build --release -p amc-cli --bin amc
out=target/schemathesis
mkdir -p "$out"
work=$(mktemp -d)
chmod 700 "$work"
log="$out/serve.log"
# With keys, as a public deployment runs: one key with every role for the
# run (so every operation is reached), and the rate limits opened wide so a
# fast fuzzer is not answered 429 throughout; `ignored_auth` checks that a
# request without the key (or with a wrong one) is refused.
key=$("$amc" keys new schemathesis admin,submit,view,publish --append "$work/keys")
"$amc" serve --addr 127.0.0.1:0 --work-dir "$work" --workers 1 --max-queued 4 \
  --max-upload-mb 8 --auth-keys "$work/keys" --key-rate 100000 \
  --max-jobs-per-tenant 1000 --log-json > "$out/serve.stdout" 2> "$log" &
pid=$!
cleanup() {
  kill "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
for _ in $(seq 100); do
  base=$(sed -n 's/^listening on //p' "$out/serve.stdout" | head -1)
  [ -n "$base" ] && break
  sleep 0.1
done
[ -n "${base:-}" ] || { echo "amc serve did not start:" >&2; cat "$log" >&2; exit 1; }
echo "schemathesis against $base for ${secs}s"
set +e
"$st" --no-color --config-file tests/schemathesis.toml run "$base/openapi.json" \
  --header "Authorization: Bearer $key" \
  --checks all --max-time "$secs" --workers 2 --max-examples 40 \
  --report junit --report-dir "$out" 2>&1 | tee "$out/run.log" | tail -40
rc=${PIPESTATUS[0]}
set -e
# A 5xx (other than 503) or a panic is logged at ERROR.
if grep -q '"level":"ERROR"' "$log"; then
  echo "the server logged errors (5xx or a panic):" >&2
  grep '"level":"ERROR"' "$log" | head -5 >&2
  rc=1
fi
# Nothing a request sent stays on disk once the service is idle.
sleep 1
left=$(find "$work" -mindepth 2 | head -5)
if [ -n "$left" ]; then
  echo "left on disk after the run:" >&2
  echo "$left" >&2
  rc=1
fi
exit "$rc"
