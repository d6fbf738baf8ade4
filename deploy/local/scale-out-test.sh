#!/usr/bin/env bash
# Scale-out test on loopback (deploy/SCALING.md): PostgreSQL (shared store) + 3 `sublevel serve`
# replicas + nginx routing by `hash $http_x_scene_id consistent` with grpc_pass.
#
#   1. routes scenes to their owners (prints which replica owns which scene);
#   2. measures Distance throughput through the proxy with 1 replica, then with 3;
#   3. kills (SIGKILL) the owner of the first scene after moving every scene's instance: its scenes
#      fail meanwhile, every other scene still answers; restarted, it serves its scenes again with
#      the moved poses (read back from PostgreSQL).
#
# Needs: PostgreSQL server binaries (/usr/lib/postgresql/*/bin or PG_BIN), nginx (Debian:
# nginx-light), a built `sublevel` (SUBLEVEL_BIN, else target/release, else target/debug).
# Bounded: the whole run is killed after 170 s. Exits 0 on success. Loopback only.
set -euo pipefail
[ -n "${SCALE_OUT_INNER:-}" ] || SCALE_OUT_INNER=1 exec timeout -k 5 170 "$0" "$@"

source "$(dirname "$0")/find-binary.sh"
PG_BIN="${PG_BIN:-$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort | tail -1)}"
[ -x "$PG_BIN/initdb" ] || { echo "no PostgreSQL server binaries (apt-get install postgresql)"; exit 2; }
command -v nginx >/dev/null || { echo "no nginx (apt-get install nginx-light)"; exit 2; }

WORK="$(mktemp -d /tmp/sublevel-scale-out.XXXXXX)"
chmod 755 "$WORK"
PIDS=()
AS_PG=()
if [ "$(id -u)" = 0 ]; then AS_PG=(runuser -u postgres --); chown postgres "$WORK"; fi
cleanup() {
  for p in "${PIDS[@]:-}"; do [ -n "$p" ] && kill "$p" 2>/dev/null || true; done
  [ -f "$WORK/nginx.pid" ] && kill "$(cat "$WORK/nginx.pid")" 2>/dev/null || true
  [ -d "$WORK/pg" ] && "${AS_PG[@]}" "$PG_BIN/pg_ctl" -D "$WORK/pg" -m immediate stop >/dev/null 2>&1 || true
  rm -rf "$WORK"
}
trap cleanup EXIT

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
PG_PORT=$(free_port); PROXY=$(free_port); PORTS=($(free_port) $(free_port) $(free_port))
STORE="postgres://postgres@127.0.0.1:$PG_PORT/postgres"
echo "== binary $BIN; PostgreSQL $PG_BIN on $PG_PORT; proxy $PROXY; replicas ${PORTS[*]}"

"${AS_PG[@]}" "$PG_BIN/initdb" -D "$WORK/pg" -U postgres -A trust >/dev/null
"${AS_PG[@]}" "$PG_BIN/pg_ctl" -D "$WORK/pg" -l "$WORK/pg.log" -w \
  -o "-c listen_addresses=127.0.0.1 -p $PG_PORT -k $WORK" start >/dev/null
echo "PostgreSQL up"

start_replica() { # index
  local i=$1
  OPENBLAS_NUM_THREADS=1 RUST_LOG=warn "$BIN" serve --addr "127.0.0.1:${PORTS[$i]}" --store "$STORE" \
    --data-dir "$WORK/unused-$i" >"$WORK/r$i.out" 2>"$WORK/r$i.err" &
  PIDS[$i]=$!
  for _ in $(seq 1 200); do
    grep -q "listening on" "$WORK/r$i.out" 2>/dev/null && return 0
    kill -0 "${PIDS[$i]}" 2>/dev/null || { cat "$WORK/r$i.err"; return 1; }
    sleep 0.05
  done
  echo "replica $i did not start"; cat "$WORK/r$i.err"; return 1
}

write_nginx() { # replica indices
  {
    echo "worker_processes 1; pid $WORK/nginx.pid; error_log $WORK/nginx-error.log warn;"
    echo "events { worker_connections 1024; }"
    echo "http {"
    echo "  access_log off; client_max_body_size 64m;"
    # nginx closes a client connection after keepalive_requests (default 1000) with a GOAWAY, and a
    # call racing that GOAWAY fails: long-lived gRPC channels need a far higher bound.
    echo "  keepalive_requests 10000000; keepalive_time 24h;"
    for t in client_body proxy fastcgi uwsgi scgi; do echo "  ${t}_temp_path $WORK/nginx-$t;"; done
    echo "  upstream sublevel {"
    echo "    hash \$http_x_scene_id consistent;"
    for i in "$@"; do echo "    server 127.0.0.1:${PORTS[$i]} max_fails=0;"; done
    echo "    keepalive 64;"
    echo "  }"
    echo "  server {"
    echo "    listen 127.0.0.1:$PROXY http2;"
    echo "    location / {"
    echo "      grpc_pass grpc://sublevel;"
    echo "      grpc_next_upstream off;"
    echo "      grpc_read_timeout 60s;"
    echo "      add_header X-Sublevel-Upstream \$upstream_addr always;"
    echo "      error_page 502 503 504 = /sublevel-unavailable;"
    echo "    }"
    echo "    # A scene whose owner is down: gRPC UNAVAILABLE (trailers-only), not an HTML error page."
    echo "    location = /sublevel-unavailable {"
    echo "      internal; default_type application/grpc;"
    echo "      add_header grpc-status 14 always;"
    echo "      add_header grpc-message \"the replica owning this scene is unavailable\" always;"
    echo "      return 204;"
    echo "    }"
    echo "  }"
    echo "}"
  } >"$WORK/nginx.conf"
}

for i in 0 1 2; do start_replica $i; done
echo "3 replicas up (store: PostgreSQL)"
write_nginx 0
nginx -p "$WORK" -c "$WORK/nginx.conf"
sleep 0.3

probe() { "$BIN" shard-probe "$@" --addr "127.0.0.1:$PROXY" --scenes-file "$WORK/scenes.txt"; }
probe setup --scenes 12
echo "== throughput through the proxy, 1 replica (127.0.0.1:${PORTS[0]})"
probe load --concurrency 6 --duration 4 | tee "$WORK/load1.txt"
write_nginx 0 1 2
nginx -p "$WORK" -c "$WORK/nginx.conf" -s reload
sleep 0.5
echo "== owners with 3 replicas (hash \$http_x_scene_id consistent)"
probe owners | tee "$WORK/owners.txt"
echo "== throughput through the proxy, 3 replicas"
probe load --concurrency 6 --duration 4 | tee "$WORK/load3.txt"
r1=$(grep -o '= [0-9]* answers/s' "$WORK/load1.txt" | grep -o '[0-9]*')
r3=$(grep -o '= [0-9]* answers/s' "$WORK/load3.txt" | grep -o '[0-9]*')
python3 -c "print(f'throughput ratio 3 replicas / 1 replica: {$r3/$r1:.2f} (ideal 3.00; $(nproc) CPUs shared by nginx, the client and the replicas)')"

echo "== move every scene (writes go to each scene's owner, then PostgreSQL)"
probe move
VICTIM_ADDR=$(head -1 "$WORK/owners.txt" | awk '{print $4}')
for i in 0 1 2; do [ "127.0.0.1:${PORTS[$i]}" = "$VICTIM_ADDR" ] && VICTIM=$i; done
OWNED=$(grep -c -- "-> $VICTIM_ADDR " "$WORK/owners.txt")
echo "== SIGKILL replica $VICTIM ($VICTIM_ADDR), owner of $OWNED of 12 scenes"
kill -9 "${PIDS[$VICTIM]}"; wait "${PIDS[$VICTIM]}" 2>/dev/null || true
set +e
probe check --moved | tee "$WORK/down.txt"
set -e
DOWN_OK=$(grep -c " ok on " "$WORK/down.txt" || true)
echo "while it is down: $DOWN_OK scenes answer, $((12 - DOWN_OK)) fail (expected $((12 - OWNED)) / $OWNED)"
[ "$DOWN_OK" = "$((12 - OWNED))" ] || { echo "FAIL: the other replicas' scenes must keep answering"; exit 1; }
echo "== restart replica $VICTIM on the same address"
start_replica "$VICTIM"
probe check --moved
probe owners
echo "scale-out test: OK"
