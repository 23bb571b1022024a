#!/usr/bin/env bash
# scripts/cluster end to end (CTest cluster_script, label integration): `up`
# with 2 extractors, 2 shards and one follower each; the two export lines it
# prints (and `env` prints the same); meshes added with `tpr add` through
# haproxy and the gateway; `tpr stats` counting them over the shards; a
# query by id; `status` listing every recorded process as running; an
# extractor killed and restarted by hand on its address shown as running
# and stopped by `down` with every recorded PID (each exits within its
# drain); --purge removing the state directory. First, `--help` prints the usage and an
# unknown command fails; then a failed start: with a stand-in
# tpr-gateway that runs but never reports its port, `up` fails naming it and
# leaves none of the processes it started running. Exit 77 (skipped)
# without haproxy.
#
#   tests/integration/cluster_script_test.sh BUILD_DIR
set -euo pipefail
BUILD="$(cd "${1:?usage: cluster_script_test.sh BUILD_DIR}" && pwd)"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
command -v haproxy >/dev/null 2>&1 || [ -x /usr/sbin/haproxy ] ||
  { echo "haproxy is not installed (scripts/setup): skipped"; exit 77; }
PATH="$PATH:/usr/sbin"
WORK="$(mktemp -d "${TMPDIR:-/tmp}/tpr-cluster-script.XXXXXX")"
export TPR_BUILD_DIR="$BUILD" TPR_CLUSTER_DIR="$WORK/state"
CLUSTER="$ROOT/scripts/cluster"
TPR="$BUILD/client/tpr"
cleanup() {
  "$CLUSTER" down --purge >/dev/null 2>&1 || true
  TPR_CLUSTER_DIR="$WORK/failing" "$CLUSTER" down >/dev/null 2>&1 || true
  if [ -s "$WORK/stand-in.pid" ]; then kill "$(cat "$WORK/stand-in.pid")" 2>/dev/null || true; fi
  rm -rf "$WORK"
}
trap cleanup EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
# running PID: the process exists and is not a zombie its parent has not
# reaped yet.
running() { [ -d "/proc/$1" ] && ! grep -q '^State:.*Z' "/proc/$1/status" 2>/dev/null; }

# Usage: --help (and `help`) print it and succeed; an unknown command prints
# it and fails.
for h in --help -h help; do
  "$CLUSTER" "$h" >"$WORK/help.txt" || fail "cluster $h failed"
  grep -q 'scripts/cluster up \[--shards N\]' "$WORK/help.txt" ||
    fail "cluster $h printed no usage"
done
if "$CLUSTER" no-such-command >"$WORK/help.txt" 2>&1; then
  fail "an unknown command succeeded"
fi
grep -q "unknown command 'no-such-command'" "$WORK/help.txt" ||
  fail "an unknown command was not named"

# A service that starts but fails its start check: a stand-in tpr-gateway
# that runs but never reports its port. `up` must fail and stop every
# process it started, the stand-in included (scripts/cluster records each
# PID as soon as the process exists).
FAKE="$WORK/stand-in-build"
mkdir -p "$FAKE"
ln -s "$BUILD/extractor/tpr-extractor" "$FAKE/tpr-extractor"
ln -s "$BUILD/indexer/tpr-indexer" "$FAKE/tpr-indexer"
cat >"$FAKE/tpr-gateway" <<EOF
#!/usr/bin/env bash
# Stand-in: notes its PID and those up recorded before it, then waits
# without reporting a port.
echo \$\$ >"$WORK/stand-in.pid"
grep -v '^gateway ' "$WORK/failing/pids" >"$WORK/started-before" || true
exec sleep 600
EOF
chmod +x "$FAKE/tpr-gateway"
if TPR_BUILD_DIR="$FAKE" TPR_CLUSTER_DIR="$WORK/failing" TPR_CLUSTER_START_SECONDS=3 \
    "$CLUSTER" up --shards 1 --extractors 1 >"$WORK/failing.log" 2>&1; then
  fail "up succeeded with a gateway that never reports its port"
fi
cat "$WORK/failing.log"
grep -q 'gateway did not report its port' "$WORK/failing.log" ||
  fail "up did not say which service failed its start check"
[ -s "$WORK/stand-in.pid" ] || fail "the stand-in gateway never ran"
mapfile -t started < <(awk '{ print $2 }' "$WORK/started-before"; cat "$WORK/stand-in.pid")
# haproxy, 1 extractor, 1 shard, the stand-in gateway
[ "${#started[@]}" = 4 ] || fail "expected 4 started processes, got: ${started[*]}"
for pid in "${started[@]}"; do
  if running "$pid"; then fail "process $pid still runs after up failed"; fi
done
[ ! -e "$WORK/failing/pids" ] || fail "up failed but left its pids file"
echo "cluster_script: a failed start check stopped all ${#started[@]} processes"

up="$("$CLUSTER" up --shards 2 --replicas 1 --extractors 2)" || fail "up failed"
echo "$up"
exports="$(grep '^export TPR_' <<<"$up")"
[ "$(wc -l <<<"$exports")" = 2 ] || fail "up printed no two export lines"
[ "$("$CLUSTER" env)" = "$exports" ] || fail "env prints other lines than up"
eval "$exports"

status="$("$CLUSTER" status)"
echo "$status"
# haproxy, 2 extractors, 2 shards, 2 followers, 1 gateway, tpr-web
[ "$(grep -c ' running$' <<<"$status")" = 9 ] || fail "not every process is running"
web_url="$(sed -n 's/^cluster: console and HTTP API at \(http:[^ ]*\)$/\1/p' <<<"$up")"
[ -n "$web_url" ] || fail "up printed no console URL"
mapfile -t pids < <(awk '{ print $2 }' "$TPR_CLUSTER_DIR/pids")

"$BUILD/extractor/tpr-synth" --out "$WORK/set" --classes 2 --poses 3 --vertices 800 \
  --seed 3 --jobs 2 >/dev/null 2>&1 || fail "tpr-synth failed"
"$TPR" add "$WORK/set" >"$WORK/add.log" 2>&1 || { cat "$WORK/add.log"; fail "tpr add failed"; }
stats="$("$TPR" --json stats)" || fail "tpr stats failed"
echo "$stats"
models="$(python3 -c 'import json, sys; print(int(json.load(sys.stdin)["models"]))' <<<"$stats")"
[ "$models" = 6 ] || fail "stats counts $models models, not 6"
first="$(sed -n '1s/ .*//p' "$WORK/set/MANIFEST.txt")"
hits="$("$TPR" --json query --id "$first" -k 3)" || fail "tpr query failed"
[ "$(grep -c '"rank"' <<<"$hits")" = 3 ] || fail "query returned other than 3 neighbours: $hits"
# The same through tpr-web in front of haproxy and the gateway.
web_models="$(python3 -c 'import json, sys, urllib.request
print(int(json.load(urllib.request.urlopen(sys.argv[1] + "api/v1/stats"))["models"]))' "$web_url")" ||
  fail "tpr-web stats failed"
[ "$web_models" = 6 ] || fail "tpr-web counts $web_models models, not 6"
web_hits="$(python3 -c 'import json, sys, urllib.parse, urllib.request
q = urllib.parse.urlencode({"id": sys.argv[2], "k": 3})
print(len(json.load(urllib.request.urlopen(sys.argv[1] + "api/v1/search?" + q))["neighbors"]))' \
  "$web_url" "$first")" || fail "tpr-web search failed"
[ "$web_hits" = 3 ] || fail "tpr-web search returned $web_hits neighbours, not 3"

# An extractor killed and started again by hand on its recorded address:
# status finds it by its address (not its recorded PID) and down stops it.
read -r _ old_pid extractor_addr < <(grep '^extractor0 ' "$TPR_CLUSTER_DIR/pids")
kill -KILL "$old_pid"
for _ in $(seq 1 100); do running "$old_pid" || break; sleep 0.1; done
"$BUILD/extractor/tpr-extractor" --listen "$extractor_addr" --threads 1 \
  >"$WORK/by-hand.log" 2>&1 </dev/null &
by_hand=$!
for _ in $(seq 1 100); do grep -q '(port ' "$WORK/by-hand.log" && break; sleep 0.1; done
grep -q '(port ' "$WORK/by-hand.log" || { cat "$WORK/by-hand.log"; fail "the restarted extractor did not serve"; }
status="$("$CLUSTER" status)"
echo "$status"
grep -q "^extractor0 .*running (pid $by_hand listens there" <<<"$status" ||
  fail "status does not see the extractor restarted by hand"

"$CLUSTER" down --purge || fail "down failed"
# Gone, or a zombie its new parent has not reaped yet.
for pid in "${pids[@]}" "$by_hand"; do
  if running "$pid"; then fail "process $pid still runs after down"; fi
done
[ ! -e "$TPR_CLUSTER_DIR" ] || fail "--purge left $TPR_CLUSTER_DIR"
echo "cluster_script: passed"
