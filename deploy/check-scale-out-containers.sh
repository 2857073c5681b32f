#!/usr/bin/env bash
# Runs the scale-out set in containers and checks it end to end (docs/scale-out.md): 3 fieldspaced
# replicas with --shared-store on one volume behind the nginx router, driven from the host through
# the router's published port with the CLI, the token and TLS (certificates of
# deploy/make-certs.sh, made in the temporary directory).
#
#   deploy/check-scale-out-containers.sh [compose|kube|all]        (from the repository root;
#                                                                    default: all = both, in turn)
#   deploy/check-scale-out-containers.sh kube-manifest             (print what kube mode plays)
#   compose: deploy/compose-scale-out.yaml under $COMPOSE (podman-compose; docker compose works
#            with ENGINE=docker COMPOSE="docker compose").
#   kube:    deploy/k8s/scale-out rendered by `kubectl kustomize`, adapted for `podman kube play`
#            (podman 4.3; see kube_manifest below for what changes and why) and played on a podman
#            network with DNS.
#
# Each set: router health; 3 uploads; 2 basis builds; a design script run twice through the router,
# once undisturbed (the reference) and once with the replica holding the session SIGKILLed
# (`$ENGINE kill -s KILL`) after 200 updates: the CLI must finish with exit status 0, all updates,
# exactly one "resumed": true and the reference's coefficients; then every replica (the killed one
# restarted) lists the same meshes and bases; then `$ENGINE stop -t 30` of replicas and router,
# each with exit status 0. Prints PASS/FAIL lines; exits 1 if any check failed, 2 on a setup error.
# Cleans up (containers, pods, volume, network, temporary files) on exit unless KEEP=1.
#
# NOT RUN IN CI: CI has no container engine. Run by hand after building the images:
#   podman build -f deploy/Dockerfile -t fieldspace .      (+ --build-arg BASE=... without Docker Hub)
#   podman build -f deploy/nginx/Containerfile -t fieldspace-router deploy/nginx
#
# Environment (defaults in brackets):
#   ENGINE                  container engine [podman]
#   COMPOSE                 compose command [podman-compose]
#   FIELDSPACE_IMAGE        the replicas' image [localhost/fieldspace:latest]
#   FIELDSPACE_NGINX_IMAGE  the router's image [localhost/fieldspace-router:latest]
#   CLIENT                  the fieldspace CLI on the host [build/bin/fieldspace]
#   MESHES                  test meshes [../shared/meshes]
#   PORT                    the router's port on the host's loopback [50151]; kube: PORT+1 too
#   EDITS                   edits in the design script [20000]
#   PYTHON                  python3 with PyYAML, for kube mode [/usr/bin/python3]
#   KEEP=1                  leave everything running (and the temporary directory) for inspection
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
MODE=${1:-all}
ENGINE=${ENGINE:-podman}
COMPOSE=${COMPOSE:-podman-compose}
FIELDSPACE_IMAGE=${FIELDSPACE_IMAGE:-localhost/fieldspace:latest}
FIELDSPACE_NGINX_IMAGE=${FIELDSPACE_NGINX_IMAGE:-localhost/fieldspace-router:latest}
CLIENT=${CLIENT:-$ROOT/build/bin/fieldspace}
MESHES=${MESHES:-$ROOT/../shared/meshes}
PORT=${PORT:-50151}
EDITS=${EDITS:-20000}
PYTHON=${PYTHON:-/usr/bin/python3}
KEEP=${KEEP:-0}

PROJECT=fscheck                    # compose project; kube: network fscheck-kube, volume fscheck-store
KUBE_NET=fscheck-kube
KUBE_STORE=fscheck-store
ADDR=127.0.0.1:$PORT
FAILURES=0
CURRENT=""                         # the set that is up: compose | kube
WORK=$(mktemp -d /tmp/fieldspace-containers.XXXXXX)

log() { printf '%s %s\n' "$(date +%H:%M:%S)" "$*"; }
pass() { printf 'PASS: %s\n' "$*"; }
fail() { printf 'FAIL: %s\n' "$*"; FAILURES=$((FAILURES + 1)); }
check() {  # check MESSAGE COMMAND...: PASS or FAIL by the command's exit status
  local message=$1
  shift
  if "$@"; then pass "$message"; else fail "$message"; fi
}
die() { printf 'FAIL: %s\n' "$*"; exit 2; }
cli() { "$CLIENT" --server "$ADDR" --tls-ca "$WORK/certs/ca.crt" --token "$WORK/token.txt" --timeout 600 "$@"; }
json_field() { "$PYTHON" -c 'import json, sys; print(json.load(sys.stdin)[sys.argv[1]])' "$1"; }
ids_of() {  # ids_of KEY: the sorted ids of a listing ({"meshes": [...]}) on stdin, one line
  "$PYTHON" -c 'import json, sys; print(" ".join(sorted(x["id"] for x in json.load(sys.stdin)[sys.argv[1]])))' "$1"
}

teardown() {
  case "$CURRENT" in
    compose)
      (cd "$ROOT/deploy" && $COMPOSE -p "$PROJECT" -f compose-scale-out.yaml down) >/dev/null 2>&1 || true
      "$ENGINE" volume rm -f "${PROJECT}_fieldspace-store" >/dev/null 2>&1 || true
      "$ENGINE" network rm "${PROJECT}_default" >/dev/null 2>&1 || true ;;
    kube)
      "$ENGINE" kube down "$WORK/kube.yaml" >/dev/null 2>&1 || true
      local v
      for v in "$KUBE_STORE" $(cat "$WORK/kube-volumes" 2>/dev/null); do
        "$ENGINE" volume rm -f "$v" >/dev/null 2>&1 || true
      done
      "$ENGINE" network rm "$KUBE_NET" >/dev/null 2>&1 || true ;;
  esac
  CURRENT=""
}
cleanup() {
  local status=$?
  if [ "$KEEP" = 1 ]; then
    log "KEEP=1: left running ($CURRENT); files in $WORK"
  else
    teardown
    rm -rf "$WORK"
  fi
  exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# --- The two ways of starting the set -------------------------------------------------------------
# Each sets REPLICAS (container names), ROUTER (container name) and TOKEN_IN (the token's path in
# the replicas).
container_of() {  # container_of LABEL_FILTERS...: the one container name matching
  "$ENGINE" ps -a "$@" --format '{{.Names}}' | head -n 1
}

start_compose() {
  CURRENT=compose
  log "compose: $COMPOSE -p $PROJECT -f deploy/compose-scale-out.yaml up -d"
  local t0=$SECONDS
  (cd "$ROOT/deploy" &&
     FIELDSPACE_IMAGE=$FIELDSPACE_IMAGE FIELDSPACE_NGINX_IMAGE=$FIELDSPACE_NGINX_IMAGE \
     FIELDSPACE_PORT=$PORT FIELDSPACE_TOKEN_FILE=$WORK/token.txt FIELDSPACE_CERTS=$WORK/certs \
     $COMPOSE -p "$PROJECT" -f compose-scale-out.yaml up -d) > "$WORK/compose-up.log" 2>&1 ||
    { tail -n 30 "$WORK/compose-up.log"; die "compose up failed"; }
  REPLICAS=()
  local s c
  for s in fieldspaced-1 fieldspaced-2 fieldspaced-3; do
    c=$(container_of --filter "label=com.docker.compose.project=$PROJECT" \
                     --filter "label=com.docker.compose.service=$s")
    [ -n "$c" ] || die "no container for service $s"
    REPLICAS+=("$c")
  done
  ROUTER=$(container_of --filter "label=com.docker.compose.project=$PROJECT" \
                        --filter "label=com.docker.compose.service=router")
  [ -n "$ROUTER" ] || die "no router container"
  TOKEN_IN=/run/secrets/fieldspace-token
  log "compose: up in $((SECONDS - t0)) s: ${REPLICAS[*]} $ROUTER"
}

# podman kube play (4.3) takes Pods, Deployments, PersistentVolumeClaims, ConfigMaps (and Secrets)
# and publishes only hostPorts. From the rendered manifests:
#  - the StatefulSet becomes one Pod per replica (fieldspaced-0..N-1, its pod template; kube play
#    has no StatefulSet); Services and PodDisruptionBudgets are dropped (no such kinds);
#  - the router Deployment comes last (nginx resolves the pod names at start; kube play starts
#    pods in file order), gets 1 replica (kube play runs one anyway) and hostPorts on 127.0.0.1
#    (PORT for gRPC, PORT+1 for /healthz); the replicas' containerPorts are dropped: kube play 4.3
#    publishes a containerPort without hostPort on the host's 0.0.0.0 at the same number;
#  - the images become $FIELDSPACE_IMAGE and $FIELDSPACE_NGINX_IMAGE;
#  - nginx.conf names the pods (podman's DNS answers pod names on a network with DNS) instead of
#    the cluster's names, without `resolver` and `resolve` (no kube-dns; nginx < 1.27.3);
#  - the Secret volumes become hostPath directories (the token's, and the certificates' of
#    deploy/make-certs.sh for fieldspace-tls): podman 4.3.1 writes a Secret volume's
#    file base64-encoded (and panics on a secret volume without `optional`);
#  - the claim fieldspace-store becomes the podman volume fscheck-store (not the README's
#    fieldspace-store of a single daemon); the ConfigMap becomes a volume of its name.
# Probes: kube play 4.3 makes podman healthchecks of exec/httpGet/tcpSocket liveness probes only
# (the grpc ones are ignored), and those need systemd timers to run.
kube_manifest() {
  kubectl kustomize "$ROOT/deploy/k8s/scale-out" > "$WORK/rendered.yaml"
  mkdir -p "$WORK/secret"
  cp "$WORK/token.txt" "$WORK/secret/token"
  chmod 755 "$WORK/secret"
  IMAGE=$FIELDSPACE_IMAGE ROUTER_IMAGE=$FIELDSPACE_NGINX_IMAGE PORT=$PORT STORE=$KUBE_STORE \
  SECRET_DIR=$WORK/secret TLS_DIR=$WORK/certs VOLUMES=$WORK/kube-volumes "$PYTHON" - "$WORK/rendered.yaml" > "$WORK/kube.yaml" <<'EOF'
import copy, os, re, sys
import yaml

env = os.environ
docs = [d for d in yaml.safe_load_all(open(sys.argv[1])) if d]
replicas = next(d["spec"]["replicas"] for d in docs if d["kind"] == "StatefulSet")

def adapt(spec):
    for c in spec["containers"]:
        if c["name"] == "fieldspaced":
            c["image"] = env["IMAGE"]
            del c["ports"]  # kube play 4.3 would publish each on the host's 0.0.0.0:50051
        elif c["name"] == "nginx":
            c["image"] = env["ROUTER_IMAGE"]
            for p in c["ports"]:
                port = {"grpc": int(env["PORT"]), "health": int(env["PORT"]) + 1}[p["name"]]
                p.update(hostPort=port, hostIP="127.0.0.1")
    for v in spec.get("volumes", []):
        if "secret" in v:
            tls = v.pop("secret")["secretName"] == "fieldspace-tls"
            v["hostPath"] = {"path": env["TLS_DIR" if tls else "SECRET_DIR"], "type": "Directory"}
        if "persistentVolumeClaim" in v:
            v["persistentVolumeClaim"]["claimName"] = env["STORE"]

out, routers = [], []
volumes = open(env["VOLUMES"], "w")
for d in docs:
    kind = d["kind"]
    if kind in ("Service", "PodDisruptionBudget"):
        continue
    if kind == "PersistentVolumeClaim":
        d["metadata"]["name"] = env["STORE"]
    elif kind == "ConfigMap":
        volumes.write(d["metadata"]["name"] + "\n")  # kube play makes a volume of it
        conf = d["data"]["nginx.conf"]
        conf, n = re.subn(r"server (fieldspaced-\d+)\.fieldspaced\.[a-z.-]+:50051 resolve ",
                          r"server \1:50051 ", conf)
        assert n == replicas, "nginx.conf names %d replicas, the StatefulSet has %d" % (n, replicas)
        conf = "".join(l for l in conf.splitlines(True)
                       if not l.strip().startswith(("resolver ", "# Re-resolve")))
        d["data"]["nginx.conf"] = conf
    elif kind == "StatefulSet":
        for i in range(replicas):
            t = copy.deepcopy(d["spec"]["template"])
            adapt(t["spec"])
            out.append({"apiVersion": "v1", "kind": "Pod",
                        "metadata": {"name": "%s-%d" % (d["metadata"]["name"], i),
                                     "labels": t["metadata"]["labels"]},
                        "spec": t["spec"]})
        continue
    elif kind == "Deployment":
        d["spec"]["replicas"] = 1
        adapt(d["spec"]["template"]["spec"])
        routers.append(d)  # last: nginx resolves the replicas' names when it starts
        continue
    out.append(d)
out += routers
yaml.SafeDumper.add_representer(str, lambda dumper, s: dumper.represent_scalar(
    "tag:yaml.org,2002:str", s, style="|" if "\n" in s else None))
yaml.safe_dump_all(out, sys.stdout, sort_keys=False)
EOF
}

start_kube() {
  CURRENT=kube
  command -v kubectl >/dev/null || die "kubectl not found (kube mode renders with kubectl kustomize)"
  kube_manifest || die "could not render/adapt deploy/k8s/scale-out"
  ! "$ENGINE" volume exists "$KUBE_STORE" 2>/dev/null || die "volume $KUBE_STORE exists: remove it"
  "$ENGINE" network create "$KUBE_NET" >/dev/null
  log "kube: $ENGINE kube play --network $KUBE_NET kube.yaml (from kubectl kustomize deploy/k8s/scale-out)"
  local t0=$SECONDS
  "$ENGINE" kube play --network "$KUBE_NET" "$WORK/kube.yaml" > "$WORK/kube-play.log" 2>&1 ||
    { tail -n 30 "$WORK/kube-play.log"; die "podman kube play failed"; }
  REPLICAS=()
  local i c
  for i in 0 1 2; do
    c=$(container_of --filter "pod=fieldspaced-$i" --filter "name=fieldspaced-$i-fieldspaced")
    [ -n "$c" ] || die "no container in pod fieldspaced-$i"
    REPLICAS+=("$c")
  done
  ROUTER=$("$ENGINE" ps -a --format '{{.Names}}' | grep -E '^fieldspace-router-.*-nginx$' | head -n 1)
  [ -n "$ROUTER" ] || die "no router container"
  TOKEN_IN=/etc/fieldspace/token
  log "kube: up in $((SECONDS - t0)) s: ${REPLICAS[*]} $ROUTER"
}

# --- The checks -----------------------------------------------------------------------------------
in_replica() {  # in_replica CONTAINER ARGS...: the image's CLI against that replica alone
  "$ENGINE" exec "$1" /usr/local/bin/fieldspace --server 127.0.0.1:50051 --token "$TOKEN_IN" \
    --tls-ca /etc/fieldspace-tls/ca.crt --tls-server-name fieldspaced --timeout 60 "${@:2}"
}
quiet() { "$@" >/dev/null 2>&1; }
running() { [ "$("$ENGINE" inspect -f '{{.State.Running}}' "$1" 2>/dev/null)" = true ]; }
ip_of() { "$ENGINE" exec "$1" hostname -I | awk '{print $1}'; }
wait_until() {  # wait_until SECONDS COMMAND...
  local deadline=$((SECONDS + $1))
  shift
  until "$@" >/dev/null 2>&1; do
    [ $SECONDS -lt $deadline ] || return 1
    sleep 0.5
  done
}

exercise() {
  local name=$1 r
  check "$name: router answers health on $ADDR" wait_until 60 "$CLIENT" --server "$ADDR" \
    --tls-ca "$WORK/certs/ca.crt" --timeout 3 health
  for r in "${REPLICAS[@]}"; do
    check "$name: $r serving" wait_until 60 in_replica "$r" health
  done
  if [ "$CURRENT" = compose ] && [ "$(basename "$ENGINE")" = podman ]; then
    for r in "${REPLICAS[@]}"; do  # the compose file's healthcheck, as podman-compose passed it
      check "$name: $ENGINE healthcheck run $r" quiet "$ENGINE" healthcheck run "$r"
    done
  fi
  if [ "$CURRENT" = kube ]; then
    check "$name: router /healthz on 127.0.0.1:$((PORT + 1))" quiet curl -fsS "http://127.0.0.1:$((PORT + 1))/healthz"
  fi
  # shellcheck disable=SC2016  # expanded in the router container
  check "$name: nginx -t in $ROUTER" "$ENGINE" exec "$ROUTER" sh -c \
    'nginx -t -c "$(ls /etc/nginx/fieldspace/nginx.conf 2>/dev/null || echo /etc/nginx/nginx.conf)" 2>&1 | tail -n 1 | grep -q successful'

  # Uploads (round robin: no key) and builds (keyed by mesh id).
  local mesh_ids=() m id t0
  for m in sphere_1k.obj eight_11k.off fertility_28k.obj; do
    id=$(cli upload "$MESHES/$m" | json_field id) || { fail "$name: upload $m"; return; }
    mesh_ids+=("$id")
  done
  pass "$name: uploaded 3 meshes through the router (${mesh_ids[*]})"
  t0=$SECONDS
  local basis big
  basis=$(cli build "${mesh_ids[0]}" --field vector --dim 100 2>"$WORK/build1.err" | json_field id) ||
    { fail "$name: build on sphere_1k: $(tail -n 3 "$WORK/build1.err")"; return; }
  big=$(cli build "${mesh_ids[2]}" --field vector --dim 60 2>"$WORK/build2.err" | json_field id) ||
    { fail "$name: build on fertility_28k: $(tail -n 3 "$WORK/build2.err")"; return; }
  pass "$name: built $basis (sphere_1k, d=100) and $big (fertility_28k, d=60) in $((SECONDS - t0)) s"

  # Which replica holds the basis: the router's access log line of a keyed call.
  cli basis "$basis" >/dev/null
  sleep 1
  local upstream holder=""
  upstream=$("$ENGINE" logs "$ROUTER" 2>/dev/null |
             awk -v key="\"$basis\"" '$2 == "/fieldspace.v1.FieldSpace/GetBasis" && $3 == key {u = $4} END {print u}')
  for r in "${REPLICAS[@]}"; do
    if [ "$(ip_of "$r")" = "${upstream%:*}" ]; then holder=$r; fi
  done
  [ -n "$holder" ] || { fail "$name: no replica at the router's upstream '$upstream' for $basis"; return; }
  pass "$name: the router sends $basis to $holder ($upstream)"

  # The reference: the design script undisturbed.
  t0=$SECONDS
  cli design "$basis" --script "$WORK/edits.jsonl" > "$WORK/ref.jsonl" 2>"$WORK/ref.err" ||
    { fail "$name: reference design run: $(tail -n 3 "$WORK/ref.err")"; return; }
  pass "$name: reference design run, $EDITS edits, $((SECONDS - t0)) s"

  # The same script; SIGKILL of the holder after 200 updates.
  cli design "$basis" --script "$WORK/edits.jsonl" > "$WORK/failover.jsonl" 2>"$WORK/failover.err" &
  local pid=$! deadline=$((SECONDS + 120)) status=0
  while [ "$(wc -l < "$WORK/failover.jsonl")" -lt 200 ] && kill -0 "$pid" 2>/dev/null &&
        [ $SECONDS -lt $deadline ]; do
    sleep 0.05
  done
  local seen
  seen=$(wc -l < "$WORK/failover.jsonl")
  "$ENGINE" kill -s KILL "$holder" >/dev/null
  log "$name: $ENGINE kill -s KILL $holder after $seen updates"
  wait "$pid" || status=$?
  check "$name: design CLI exit status 0 after the kill (got $status)" [ "$status" = 0 ]
  if [ "$seen" -lt 200 ] || [ "$seen" -gt "$EDITS" ]; then
    fail "$name: killed after $seen updates (script too short?)"
  fi
  local verdict
  verdict=$("$PYTHON" - "$WORK/ref.jsonl" "$WORK/failover.jsonl" "$EDITS" <<'EOF'
import json, sys
ref = [json.loads(l) for l in open(sys.argv[1])]
out = [json.loads(l) for l in open(sys.argv[2])]
edits = int(sys.argv[3])
resumed = [i for i, u in enumerate(out) if u.get("resumed")]
worst = 0.0
same = len(ref) == len(out)
for a, b in zip(ref, out):
    same &= a["edit"] == b["edit"] and a["num_constraints"] == b["num_constraints"]
    scale = max([1.0] + [abs(x) for x in a["coefficients"]])
    worst = max([worst] + [abs(x - y) / scale for x, y in zip(a["coefficients"], b["coefficients"])])
    same &= len(a["coefficients"]) == len(b["coefficients"])
ok = (len(ref) == len(out) == edits + 1 and len(resumed) == 1 and same and worst <= 1e-9
      and not any(u.get("resumed") for u in ref))
print("%s updates=%d/%d resumed_at=%s max_rel_diff=%.3g" %
      ("ok" if ok else "bad", len(out), edits + 1, resumed, worst))
EOF
)
  check "$name: failover: $verdict (vs the reference run)" [ "${verdict%% *}" = ok ]
  grep -h -m 1 '"resumed":true' "$WORK/failover.jsonl" | cut -c 1-200 | sed 's/^/    /'

  # Listings: the router, every live replica, then the killed one after a restart.
  local want_m want_b
  want_m=$(printf '%s\n' "${mesh_ids[@]}" | sort | tr '\n' ' ' | sed 's/ $//')
  want_b=$(printf '%s\n' "$basis" "$big" | sort | tr '\n' ' ' | sed 's/ $//')
  check "$name: router lists the 3 meshes" [ "$(cli meshes | ids_of meshes)" = "$want_m" ]
  check "$name: router lists the 2 bases" [ "$(cli bases | ids_of bases)" = "$want_b" ]
  # Calls without a key go round robin: once nginx retries the dead replica (10 s after marking it
  # failed), connecting to its vanished address must give up quickly (grpc_connect_timeout).
  sleep 11
  local i slow=0 t
  for i in 1 2 3 4; do
    t0=$(date +%s%N)
    quiet cli meshes || slow=$((slow + 100))
    t=$((($(date +%s%N) - t0) / 1000000))
    [ "$t" -lt 5000 ] || slow=$((slow + 1))
    log "$name: meshes through the router, 11+ s after the kill: $t ms"
  done
  check "$name: un-keyed calls after the kill answer within 5 s each" [ "$slow" = 0 ]
  if ! running "$holder"; then
    "$ENGINE" start "$holder" >/dev/null 2>>"$WORK/engine.log"
    log "$name: restarted $holder"
  else
    log "$name: $holder was restarted by its restart policy"
  fi
  check "$name: $holder serving again" wait_until 60 in_replica "$holder" health
  for r in "${REPLICAS[@]}"; do
    check "$name: $r lists the same meshes" [ "$(in_replica "$r" meshes | ids_of meshes)" = "$want_m" ]
    check "$name: $r lists the same bases" [ "$(in_replica "$r" bases | ids_of bases)" = "$want_b" ]
    check "$name: $r loads $big" quiet in_replica "$r" basis "$big"
  done

  # Clean stop: SIGTERM drains and exits 0; nginx stops on SIGQUIT (its STOPSIGNAL) with 0.
  t0=$SECONDS
  "$ENGINE" stop -t 30 "${REPLICAS[@]}" >/dev/null 2>>"$WORK/engine.log"
  log "$name: $ENGINE stop -t 30 of the replicas took $((SECONDS - t0)) s"
  "$ENGINE" stop -t 30 "$ROUTER" >/dev/null 2>>"$WORK/engine.log"
  for r in "${REPLICAS[@]}" "$ROUTER"; do
    local code
    code=$("$ENGINE" inspect -f '{{.State.ExitCode}}' "$r")
    check "$name: $r stopped with exit status 0 (got $code)" [ "$code" = 0 ]
  done
}

if [ "$MODE" = kube-manifest ]; then  # print what kube mode plays, and stop
  (umask 022; echo token > "$WORK/token.txt")
  sh "$ROOT/deploy/make-certs.sh" "$WORK/certs" >/dev/null
  kube_manifest
  cat "$WORK/kube.yaml"
  exit 0
fi

# --- Preconditions --------------------------------------------------------------------------------
[ -x "$CLIENT" ] || die "CLIENT $CLIENT is not an executable (build the project or set CLIENT)"
for m in sphere_1k.obj eight_11k.off fertility_28k.obj; do
  [ -f "$MESHES/$m" ] || die "mesh $MESHES/$m missing (set MESHES)"
done
for image in "$FIELDSPACE_IMAGE" "$FIELDSPACE_NGINX_IMAGE"; do
  "$ENGINE" image exists "$image" 2>/dev/null || "$ENGINE" image inspect "$image" >/dev/null 2>&1 ||
    die "image $image not found (build it first, see the top of this script)"
done
for p in "$PORT" $((PORT + 1)); do
  if (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null; then die "port $p is in use (set PORT)"; fi
done
(umask 022; od -An -N32 -tx1 /dev/urandom | tr -d ' \n' > "$WORK/token.txt"; echo >> "$WORK/token.txt")
sh "$ROOT/deploy/make-certs.sh" "$WORK/certs" >/dev/null
"$PYTHON" - "$EDITS" > "$WORK/edits.jsonl" <<'EOF'
import sys
edits = int(sys.argv[1])
for i in range(1, 9):  # 8 soft constraints, then moves of them (sphere_1k has 1280 faces)
    print('{"add": {"id": %d, "face": %d, "vector": [1, 0, 0]}}' % (i, 10 * i))
for k in range(edits - 8):
    print('{"move": {"id": %d, "face": %d, "vector": [0, %d, 1]}}' % (1 + k % 8, (37 * k) % 1280, 1 + k % 3))
EOF
log "$("$ENGINE" --version); client $CLIENT; work dir $WORK"

case "$MODE" in
  compose) sets=(compose) ;;
  kube) sets=(kube) ;;
  all) sets=(compose kube) ;;
  *) die "usage: $0 [compose|kube|all]" ;;
esac
for set in "${sets[@]}"; do
  "start_$set"
  exercise "$set"
  if [ "$KEEP" = 1 ]; then
    log "KEEP=1: stopping after $set"
    break
  fi
  teardown
done
if [ "$FAILURES" -gt 0 ]; then
  printf 'FAIL: %d check(s) failed\n' "$FAILURES"
  exit 1
fi
printf 'PASS: all checks (%s)\n' "${sets[*]}"
