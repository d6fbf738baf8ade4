#!/usr/bin/env bash
# Runs `sublevel serve` the way deploy/Dockerfile and deploy/k8s run it, without a container engine
# (this project's machines have the docker CLI but no engine):
#
#   non-root        uid/gid 65534 (setpriv), no new privileges, no supplementary groups
#   read-only root  a private mount namespace (unshare -m) whose / is remounted read-only; only the
#                   data volume (a bind mount of a temp directory, owned by that uid) is writable
#   environment     OPENBLAS_NUM_THREADS=1, RUST_LOG=info, the image's production command
#                   (serve --addr … --data-dir /data-like volume, no --demo)
#   healthcheck     `sublevel health` (the compose / Dockerfile HEALTHCHECK command)
#   SIGTERM         sent while clients are querying: the exit must be clean (status 0) and within
#                   the shutdown grace (default 10 s); a restart finds the data on the volume
#
# Root is needed for the namespace and the uid switch; without it the test runs as the current
# user on a read-write root and says so. Bounded (120 s). Exits 0 on success.
set -euo pipefail
[ -n "${CONTAINER_LIKE_INNER:-}" ] || CONTAINER_LIKE_INNER=1 exec timeout -k 5 120 "$0" "$@"

source "$(dirname "$0")/find-binary.sh"
GRACE="${GRACE:-10}"
WORK="$(mktemp -d /tmp/sublevel-container-like.XXXXXX)"
DATA="$WORK/data"; mkdir -p "$DATA"
chmod 755 "$WORK"
PID=""
cleanup() { [ -n "$PID" ] && kill -9 "$PID" 2>/dev/null || true; rm -rf "$WORK"; }
trap cleanup EXIT
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
ADDR="127.0.0.1:$PORT"

ISOLATED=0
if [ "$(id -u)" = 0 ] && unshare -m --propagation private true 2>/dev/null; then
  ISOLATED=1
  chown 65534:65534 "$DATA"
  # The binary must be readable by uid 65534 (it is world-readable in the image too).
  cp "$BIN" "$WORK/sublevel"; chmod 755 "$WORK/sublevel"; BIN="$WORK/sublevel"
  echo "== emulating the container: uid 65534, read-only /, writable volume $DATA (no container engine here)"
else
  echo "== NOT isolated (needs root and mount namespaces): running as $(id -un) on a read-write root"
fi

start() {
  : >"$WORK/out"; : >"$WORK/err"
  if [ "$ISOLATED" = 1 ]; then
    unshare -m --propagation private sh -c "mount --bind '$DATA' '$DATA' && mount -o remount,bind,ro / && \
      exec setpriv --reuid=65534 --regid=65534 --clear-groups --no-new-privs \
      env -i PATH=/usr/bin:/bin HOME=/nonexistent RUST_LOG=info OPENBLAS_NUM_THREADS=1 \
      '$BIN' serve --addr '$ADDR' --data-dir '$DATA' --shutdown-grace ${GRACE}s" >"$WORK/out" 2>"$WORK/err" &
  else
    env RUST_LOG=info OPENBLAS_NUM_THREADS=1 "$BIN" serve --addr "$ADDR" --data-dir "$DATA" \
      --shutdown-grace "${GRACE}s" >"$WORK/out" 2>"$WORK/err" &
  fi
  PID=$!
  for _ in $(seq 1 300); do
    grep -q "listening on" "$WORK/out" && return 0
    kill -0 "$PID" 2>/dev/null || { echo "server exited:"; cat "$WORK/err"; exit 1; }
    sleep 0.05
  done
  echo "server did not start"; cat "$WORK/err"; exit 1
}

start
echo "server pid $PID: $(grep -E '^(Uid|Gid|Groups|NoNewPrivs):' /proc/$PID/status | tr -s '\t ' ' ' | paste -sd';')"
if [ "$ISOLATED" = 1 ]; then
  [ "$(awk '/^Uid:/{print $2}' /proc/$PID/status)" = 65534 ] || { echo "FAIL: not running as 65534"; exit 1; }
  if nsenter -t "$PID" -m touch /sublevel-root-write-test 2>"$WORK/touch.err"; then
    echo "FAIL: the root file system is writable"; exit 1
  fi
  echo "root file system in the server's namespace: $(cat "$WORK/touch.err")"
fi
echo "== healthcheck: $("$BIN" health --addr "$ADDR")"

"$BIN" shard-probe setup --addr "$ADDR" --scenes-file "$WORK/scenes.txt" --scenes 4
echo "data volume after the writes: $(ls "$DATA" | paste -sd' ')"

echo "== SIGTERM while 4 clients query (grace ${GRACE} s)"
"$BIN" shard-probe load --addr "$ADDR" --scenes-file "$WORK/scenes.txt" --duration 6 --concurrency 4 \
  >"$WORK/load.out" 2>&1 &
LOAD=$!
sleep 1
T0=$(date +%s.%N)
kill -TERM "$PID"
set +e
wait "$PID"; CODE=$?
set -e
T1=$(date +%s.%N)
PID=""
EXIT_S=$(python3 -c "print(f'{$T1-$T0:.3f}')")
wait "$LOAD" 2>/dev/null || true
echo "exit status $CODE after $EXIT_S s"
echo "load client (its calls fail once the server is gone, as expected): $(tail -1 "$WORK/load.out")"
grep -E "shutting down|server stopped" "$WORK/err" | sed 's/\x1b\[[0-9;]*m//g; s/^/  log: /' | head -3
[ "$CODE" = 0 ] || { echo "FAIL: exit status $CODE"; cat "$WORK/err" | tail -5; exit 1; }
python3 -c "import sys; sys.exit(0 if $T1-$T0 <= $GRACE + 1 else 1)" || { echo "FAIL: exit took longer than the grace"; exit 1; }

echo "== restart on the same volume"
start
"$BIN" shard-probe check --addr "$ADDR" --scenes-file "$WORK/scenes.txt"
kill -TERM "$PID"; wait "$PID" || true; PID=""
echo "container-like test: OK"
