#!/usr/bin/env bash
# A local fleet (docs/scale-out.md): N fieldspaced replicas with --shared-store on one store
# directory, on loopback ports, behind nginx on loopback as the gRPC router (the configuration of
# deploy/nginx/fieldspace-router.conf without TLS: grpc_pass to an upstream hashed on the routing
# key x-fieldspace-key). Prints one line per replica and for nginx, then `router: 127.0.0.1:PORT`
# once every replica and the router answer health, and runs until SIGINT (Ctrl-C) or SIGTERM,
# which stops nginx and the replicas and removes the script's temporary folder (with the store
# unless --store / $STORE named one).
#
# usage: deploy/local-fleet.sh [-n N] [--port P] [--bin-dir DIR] [--store DIR] [-- DAEMON_ARGS...]
#   -n N           replicas (default 3; env N)
#   --port P       the router's port on 127.0.0.1 (default 50100; 0: a free port; env PORT)
#   --bin-dir DIR  where fieldspaced and fieldspace are (default: build/bin of this checkout;
#                  env BIN_DIR)
#   --store DIR    the shared store, kept at the end (default: in the temporary folder; env STORE)
#   DAEMON_ARGS    passed to every replica (e.g. --threads 1 --memory-budget-mb 1024)
# nginx: $NGINX, else nginx on PATH, else /usr/sbin/nginx (Debian: apt-get install nginx-light).
set -euo pipefail

usage() { sed -n '10,17s/^# \{0,1\}//p' "$0" >&2; exit 2; }

replicas=${N:-3}
router_port=${PORT:-50100}
bin_dir=${BIN_DIR:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/build/bin}
store=${STORE:-}
daemon_args=()
while [ $# -gt 0 ]; do
  case $1 in
    -n) [ $# -ge 2 ] || usage; replicas=$2; shift 2 ;;
    --port) [ $# -ge 2 ] || usage; router_port=$2; shift 2 ;;
    --bin-dir) [ $# -ge 2 ] || usage; bin_dir=$2; shift 2 ;;
    --store) [ $# -ge 2 ] || usage; store=$2; shift 2 ;;
    --) shift; daemon_args=("$@"); break ;;
    -h | --help) usage ;;
    *) echo "local-fleet: unknown argument '$1'" >&2; usage ;;
  esac
done
[[ $replicas =~ ^[1-9][0-9]*$ ]] || { echo "local-fleet: -n needs a count >= 1" >&2; exit 2; }
if ! [[ $router_port =~ ^[0-9]+$ ]] || [ "$router_port" -gt 65535 ]; then
  echo "local-fleet: --port needs 0..65535" >&2
  exit 2
fi
daemon=$bin_dir/fieldspaced
cli=$bin_dir/fieldspace
for b in "$daemon" "$cli"; do
  [ -x "$b" ] || { echo "local-fleet: $b not found (build first, or --bin-dir)" >&2; exit 1; }
done
nginx=${NGINX:-$(command -v nginx || echo /usr/sbin/nginx)}
[ -x "$nginx" ] || { echo "local-fleet: nginx not found (apt-get install nginx-light)" >&2; exit 1; }

port_in_use() { (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }
port_taken() { echo "local-fleet: 127.0.0.1:$1 is in use (--port P, or --port 0: a free one)" >&2; }
if [ "$router_port" != 0 ] && port_in_use "$router_port"; then port_taken "$router_port"; exit 1; fi

work=$(mktemp -d "${TMPDIR:-/tmp}/fieldspace-fleet.XXXXXX")
[ -n "$store" ] || store=$work/store
pids=()
nginx_pid=

# shellcheck disable=SC2317  # called by the EXIT trap
cleanup() {
  trap - EXIT INT TERM
  [ -z "$nginx_pid" ] || kill -TERM "$nginx_pid" 2>/dev/null || true
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  # Replicas drain for up to --drain-seconds (10 s by default); then they are killed.
  local deadline=$((SECONDS + 15))
  for p in "${pids[@]}" ${nginx_pid:+"$nginx_pid"}; do
    while kill -0 "$p" 2>/dev/null && [ "$SECONDS" -lt "$deadline" ]; do sleep 0.1; done
    kill -KILL "$p" 2>/dev/null || true
    wait "$p" 2>/dev/null || true
  done
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# --- The replicas, each on a free port (fieldspaced prints the one it got).
addresses=()
for k in $(seq 1 "$replicas"); do
  : >"$work/replica-$k.out"  # before the replica's own redirection: read below at once
  "$daemon" --listen 127.0.0.1:0 --store "$store" --shared-store --daemon-id "replica-$k" \
    "${daemon_args[@]}" >"$work/replica-$k.out" 2>"$work/replica-$k.log" &
  pids+=($!)
  address=
  for _ in $(seq 300); do
    address=$(sed -n 's/^listening on //p' "$work/replica-$k.out")
    [ -z "$address" ] || break
    kill -0 "${pids[-1]}" 2>/dev/null ||
      { echo "local-fleet: replica-$k exited:" >&2; tail -20 "$work/replica-$k.log" >&2; exit 1; }
    sleep 0.1
  done
  [ -n "$address" ] || { echo "local-fleet: replica-$k did not listen within 30 s" >&2; exit 1; }
  addresses+=("$address")
  echo "replica: ${pids[-1]} $address replica-$k"
done

# --- nginx, run as this user with its files in $work; port 0: try random unused ports.
write_conf() {
  local user=""
  [ "$(id -u)" != 0 ] || user="user $(id -un);"
  {
    echo "$user"
    cat <<EOF
worker_processes 1;
daemon off;
pid $work/nginx.pid;
error_log $work/nginx-error.log warn;
events { worker_connections 1024; }
http {
    log_format keyed '\$remote_addr \$request_uri "\$http_x_fieldspace_key" \$upstream_addr '
                     '\$status \$request_time';
    access_log $work/nginx-access.log keyed;
    client_body_temp_path $work/client_body;
    proxy_temp_path $work/proxy;
    fastcgi_temp_path $work/fastcgi;
    uwsgi_temp_path $work/uwsgi;
    scgi_temp_path $work/scgi;
    upstream fieldspace {
        hash \$http_x_fieldspace_key consistent;
EOF
    for a in "${addresses[@]}"; do
      echo "        server $a max_fails=1 fail_timeout=10s;"
    done
    cat <<EOF
        keepalive 32;
    }
    server {
        listen 127.0.0.1:$1 http2;
        client_max_body_size 0;
        grpc_read_timeout 3600s;
        grpc_send_timeout 3600s;
        grpc_connect_timeout 3s;
        location / {
            grpc_pass grpc://fieldspace;
            grpc_next_upstream error timeout;
        }
    }
}
EOF
  } >"$work/nginx.conf"
}

for attempt in $(seq 20); do
  port=$router_port
  if [ "$router_port" = 0 ]; then
    port=$((20000 + RANDOM % 30000))
    ! port_in_use "$port" || continue
  elif port_in_use "$port"; then
    port_taken "$port"
    exit 1
  fi
  write_conf "$port"
  "$nginx" -p "$work" -c "$work/nginx.conf" -e "$work/nginx-error.log" \
    >>"$work/nginx.out" 2>&1 &
  nginx_pid=$!
  for _ in $(seq 100); do
    ! port_in_use "$port" || break
    kill -0 "$nginx_pid" 2>/dev/null || break
    sleep 0.1
  done
  if kill -0 "$nginx_pid" 2>/dev/null && port_in_use "$port"; then
    break
  fi
  kill -KILL "$nginx_pid" 2>/dev/null || true
  wait "$nginx_pid" 2>/dev/null || true
  nginx_pid=
  if [ "$router_port" != 0 ] || [ "$attempt" = 20 ]; then
    echo "local-fleet: nginx did not listen on 127.0.0.1:$port:" >&2
    tail -5 "$work/nginx-error.log" "$work/nginx.out" >&2 2>/dev/null || true
    exit 1
  fi
done
echo "nginx: $nginx_pid"

# --- Ready when every replica answers health, directly and (round robin: calls without a routing
# key) through the router.
health() { "$cli" --server "$1" --timeout 5 health >/dev/null 2>&1; }
for a in "${addresses[@]}"; do
  for _ in $(seq 100); do ! health "$a" || continue 2; sleep 0.1; done
  echo "local-fleet: replica $a does not answer health" >&2
  exit 1
done
for _ in $(seq 0 "$replicas"); do
  health "127.0.0.1:$port" || { echo "local-fleet: no health through the router" >&2; exit 1; }
done
kill -0 "$nginx_pid" 2>/dev/null || { echo "local-fleet: nginx exited" >&2; exit 1; }
echo "work: $work"
echo "router: 127.0.0.1:$port"

# Until a signal (the traps above) or nginx's end. A replica's death is not the end: its keys move
# to the next replica on nginx's ring.
rc=0
wait "$nginx_pid" || rc=$?
nginx_pid=
echo "local-fleet: nginx exited ($rc)" >&2
exit 1
