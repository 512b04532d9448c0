#!/usr/bin/env bash
# Make a development certificate authority and certificates for crossway's mutual TLS.
#
#   deploy/make-certs.sh [DIR] [HOSTNAME...]
#
# Writes into DIR (default deploy/certs): ca.pem/ca.key (the CA), learner.pem/learner.key (the
# learner's or router's server certificate, valid for the given host names and IP addresses,
# default localhost and 127.0.0.1), actor.pem/actor.key (a client certificate every actor
# presents). For development only: keep ca.key away from the machines that run actors.
set -euo pipefail
dir=${1:-deploy/certs}
shift || true
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(localhost 127.0.0.1)
mkdir -p "$dir"
cd "$dir"
san=""
for name in "${names[@]}"; do
    if [[ $name =~ ^[0-9.]+$ ]]; then san+="IP:$name,"; else san+="DNS:$name,"; fi
done
san=${san%,}
days=825
openssl req -x509 -newkey rsa:2048 -nodes -days "$days" -keyout ca.key -out ca.pem \
    -subj "/CN=crossway dev CA" -addext "basicConstraints=critical,CA:TRUE" \
    -addext "keyUsage=critical,keyCertSign,cRLSign" 2>/dev/null
make_leaf() {  # name common-name extended-key-usage [subject-alt-names]
    openssl req -newkey rsa:2048 -nodes -keyout "$1.key" -out "$1.csr" -subj "/CN=$2" 2>/dev/null
    {
        echo "basicConstraints=CA:FALSE"
        echo "keyUsage=critical,digitalSignature,keyEncipherment"
        echo "extendedKeyUsage=$3"
        [ -n "${4:-}" ] && echo "subjectAltName=$4"
    } > "$1.ext"
    openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -days "$days" \
        -extfile "$1.ext" -out "$1.pem" 2>/dev/null
    rm -f "$1.csr" "$1.ext"
}
make_leaf learner "${names[0]}" serverAuth,clientAuth "$san"
make_leaf actor "crossway actor" clientAuth,serverAuth "$san"
chmod 600 ./*.key
echo "wrote $(pwd): ca.pem, learner.pem/.key (for ${names[*]}), actor.pem/.key"
