#!/usr/bin/env bash
# The whole suite on a bare Debian 12: debootstrap's minbase (made once, kept in podman's store
# as localhost/camo-debian:bookworm), this commit's files, the README's apt-get line and nothing
# else, then `./camo test`. The container tests are left out: they build containers, and this
# runs in one. Run from the repository root, as root:  bash tools/bare_debian_test.sh [pytest args]
# (docs/containers.md gives its last result).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BASE=localhost/camo-debian:bookworm
export CONTAINERS_CONF="$ROOT/tests/containers.conf"
for tool in podman debootstrap git; do
    command -v "$tool" >/dev/null || { echo "bare_debian_test: needs $tool (apt-get install podman runc debootstrap git)" >&2; exit 2; }
done
work="$(mktemp -d /var/tmp/camo-bare.XXXXXX)"
trap 'rm -rf "$work"' EXIT
if ! podman image exists "$BASE"; then
    debootstrap --variant=minbase bookworm "$work/root" >"$work/debootstrap.log"
    tar -C "$work/root" -c . | podman import - "$BASE" >/dev/null
    rm -rf "$work/root"
fi
mkdir "$work/camo"
git -C "$ROOT" archive HEAD | tar -x -C "$work/camo"
ca="${PIP_CERT:-${SSL_CERT_FILE:-}}"
certs=()
if [[ -n "$ca" && -f "$ca" ]]; then
    certs=(-v "$ca:/etc/camo-ca.crt:ro" -e PIP_CERT=/etc/camo-ca.crt -e NODE_EXTRA_CA_CERTS=/etc/camo-ca.crt
           -e npm_config_cafile=/etc/camo-ca.crt)
fi
# Host networking (the packages' registries; the network tests make namespaces of their own) and
# privileges (iptables, namespaces), as a developer's machine has them.
podman run --rm --network host --privileged --shm-size 2g "${certs[@]}" -v "$work/camo:/camo" \
    -w /camo "$BASE" bash -c '
        set -euo pipefail
        export DEBIAN_FRONTEND=noninteractive
        line="$(grep -m1 "apt-get install" README.md | sed "s/^sudo //")"
        echo "+ $line"
        apt-get update -qq
        $line -y -qq >/dev/null
        test ! -s /etc/machine-id && echo "(no /etc/machine-id)"
        ./camo test -q --ignore tests/test_containers.py "$@"' bare "$@"
