#!/bin/sh
# Makes a private CA and the certificates of fieldspaced's TLS (--tls-cert, --tls-key,
# --tls-client-ca) with the openssl CLI:
#   deploy/make-certs.sh DIR [NAME ...]
# DIR (created) gets, as PEM files named like the keys of a Kubernetes TLS Secret:
#   ca.crt, ca.key       the CA (clients' --tls-ca; servers' --tls-client-ca for mutual TLS).
#                        Keep ca.key off the servers: it only signs.
#   tls.crt, tls.key     the server certificate of every daemon and the router, for the names
#                        fieldspaced (what the health checks and the router expect, with
#                        --tls-server-name / grpc_ssl_name), fieldspace-router, localhost,
#                        127.0.0.1, ::1 and each NAME (a DNS name, or an IP address).
#   client.crt, client.key  a client certificate of the CA (--tls-cert / --tls-key of the CLI).
# EC P-256 keys, valid DAYS days (environment; default 825). ca.key is private to its owner;
# tls.key and client.key are readable by all (mode 0644) so that the containers' users (10001,
# nginx's 101) can read a bind-mounted copy (deploy/compose*.yaml): keep DIR where only you can
# reach it, or copy the keys with tighter modes and owners.
set -eu
if [ $# -lt 1 ]; then
  echo "usage: $0 DIR [NAME ...]" >&2
  exit 2
fi
dir=$1
shift
days=${DAYS:-825}
sans="DNS:fieldspaced, DNS:fieldspace-router, DNS:localhost, IP:127.0.0.1, IP:::1"
for name in "$@"; do
  if printf '%s' "$name" | grep -Eq '^([0-9.]+|[0-9a-fA-F:]*:[0-9a-fA-F:]*)$'; then
    sans="$sans, IP:$name"
  else
    sans="$sans, DNS:$name"
  fi
done
mkdir -p "$dir"
cnf=$dir/openssl.cnf
cat > "$cnf" <<EOF
[req]
distinguished_name = dn
prompt = no
[dn]
CN = fieldspace
[ca]
basicConstraints = critical, CA:TRUE
keyUsage = critical, keyCertSign, cRLSign
subjectKeyIdentifier = hash
[server]
basicConstraints = CA:FALSE
keyUsage = critical, digitalSignature
extendedKeyUsage = serverAuth
subjectAltName = $sans
[client]
basicConstraints = CA:FALSE
keyUsage = critical, digitalSignature
extendedKeyUsage = clientAuth
EOF
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }
(umask 077; key "$dir/ca.key")
openssl req -config "$cnf" -x509 -new -key "$dir/ca.key" -days "$days" -subj "/CN=fieldspace CA" \
  -extensions ca -out "$dir/ca.crt"
serial=$(date +%s)
for leaf in tls client; do
  key "$dir/$leaf.key"
  chmod 0644 "$dir/$leaf.key"
  openssl req -config "$cnf" -new -key "$dir/$leaf.key" -subj "/CN=fieldspace $leaf" \
    -out "$dir/$leaf.csr"
  serial=$((serial + 1))
  openssl x509 -req -in "$dir/$leaf.csr" -CA "$dir/ca.crt" -CAkey "$dir/ca.key" \
    -set_serial "$serial" -days "$days" -extfile "$cnf" \
    -extensions "$([ $leaf = tls ] && echo server || echo client)" -out "$dir/$leaf.crt" 2>/dev/null
  rm -f "$dir/$leaf.csr"
done
rm -f "$cnf"
chmod 0644 "$dir/ca.crt" "$dir/tls.crt" "$dir/client.crt"
echo "$dir: ca.crt ca.key tls.crt tls.key client.crt client.key (server names: $sans)"
