#!/usr/bin/env bash
# A private certificate authority and one TLS certificate per worker host, for photon on a lab network.
#
#   bash deploy/tls/make-certs.sh OUT_DIR HOST [HOST...]
#
# Writes OUT_DIR/ca.pem (give it to the coordinator: --tls-ca, or `tls_ca` in the host list), OUT_DIR/ca.key
# (keep it private, off the workers), and for each HOST: OUT_DIR/HOST.pem and OUT_DIR/HOST.key (copy them to
# that worker: photon-worker --tls-cert HOST.pem --tls-key HOST.key). HOST is the name or IP address the
# coordinator uses to reach the worker; the certificate names exactly that. Keys are P-256 ECDSA; certificates
# last 825 days. Running it again keeps an existing CA and (re)issues the host certificates.
set -euo pipefail
if [ $# -lt 2 ]; then
  sed -n '2,11p' "$0" >&2
  exit 2
fi
out=$1
shift
command -v openssl >/dev/null || { echo "openssl is needed (apt-get install openssl)" >&2; exit 1; }
mkdir -p "$out"
umask 077

if [ ! -f "$out/ca.pem" ]; then
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 3650 \
    -keyout "$out/ca.key" -out "$out/ca.pem" -subj "/CN=photon farm CA" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" 2>/dev/null
  echo "new authority: $out/ca.pem"
fi

for host in "$@"; do
  if [[ $host =~ ^[0-9.]+$ || $host == *:* ]]; then san="IP:$host"; else san="DNS:$host"; fi
  ext=$(mktemp)
  printf '%s\n' "basicConstraints=critical,CA:FALSE" "keyUsage=critical,digitalSignature" \
    "extendedKeyUsage=serverAuth" "subjectAltName=$san" >"$ext"
  openssl req -new -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes \
    -keyout "$out/$host.key" -out "$out/$host.csr" -subj "/CN=$host" 2>/dev/null
  openssl x509 -req -in "$out/$host.csr" -CA "$out/ca.pem" -CAkey "$out/ca.key" -CAcreateserial \
    -days 825 -sha256 -extfile "$ext" -out "$out/$host.pem" 2>/dev/null
  rm -f "$ext" "$out/$host.csr"
  echo "worker certificate: $out/$host.pem ($san), key $out/$host.key"
done
chmod 644 "$out/ca.pem" "$out"/*.pem
