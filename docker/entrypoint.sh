#!/bin/sh
# Entrypoint of the HapCo image (docker/Dockerfile, docs/container.md).
# - HAPCO_DDS_INTERFACE defaults to the interface of the default route (eth0 on a container
#   network, the host's uplink with --network host), else lo; docker/cyclonedds.xml reads it.
# - HAPCO_DDS_PEERS names are expanded to every address they resolve to (scaled services).
# - "IMAGE --flags..." runs hapco-server on $HAPCO_SCENE with those flags.
# - HAPCO_DOMAIN, if set, becomes --domain for the hapco-* tools (a later --domain wins).
# - hapco-phantom without --client-id gets HAPCO_CLIENT_ID, else the container's hostname
#   (unique per compose replica).
# - HAPCO_SECURITY_DIR, if set, becomes --security for the hapco-* tools: secured DDS with a
#   deployment of scripts/dds-security mounted read-only there (DIR/public and the tool's own
#   DIR/NAME; docs/security.md).
set -eu

if [ -z "${HAPCO_DDS_INTERFACE:-}" ]; then
  # /proc/net/route: Iface Destination ...; destination 00000000 = the default route.
  while read -r iface destination _; do
    if [ "$destination" = "00000000" ]; then HAPCO_DDS_INTERFACE=$iface; break; fi
  done < /proc/net/route || true
  export HAPCO_DDS_INTERFACE="${HAPCO_DDS_INTERFACE:-lo}"
fi

# A peer name that resolves to several addresses (a compose service scaled to several
# replicas: `--scale server=3`) becomes all of them, so every replica is discovered; Cyclone
# itself would take one address per name. Names that do not resolve (yet) stay as they are.
if [ -n "${HAPCO_DDS_PEERS:-}" ] && command -v getent >/dev/null 2>&1; then
  expanded=""
  old_ifs=$IFS
  IFS=,
  for peer in $HAPCO_DDS_PEERS; do
    addresses=$(getent ahostsv4 "$peer" 2>/dev/null | awk '{print $1}' | sort -u | tr '\n' ',' | sed 's/,$//')
    expanded="${expanded:+$expanded,}${addresses:-$peer}"
  done
  IFS=$old_ifs
  export HAPCO_DDS_PEERS="$expanded"
fi

if [ "$#" -eq 0 ] || [ "${1#-}" != "$1" ]; then
  set -- hapco-server "${HAPCO_SCENE:-/usr/share/hapco/scenes/benchmark1.txtpb}" "$@"
fi

program=$1
shift
case "$program" in
  hapco-phantom)
    has_id=no
    for arg in "$@"; do
      if [ "$arg" = "--client-id" ]; then has_id=yes; fi
    done
    if [ "$has_id" = no ]; then
      set -- --client-id "${HAPCO_CLIENT_ID:-${HOSTNAME:-$(cat /proc/sys/kernel/hostname)}}" "$@"
    fi
    ;;
esac
case "$program" in
  hapco-server | hapco-phantom | hapco-recorder | hapco-status)
    if [ -n "${HAPCO_DOMAIN:-}" ]; then set -- --domain "$HAPCO_DOMAIN" "$@"; fi
    if [ -n "${HAPCO_SECURITY_DIR:-}" ]; then set -- --security "$HAPCO_SECURITY_DIR" "$@"; fi
    ;;
esac
exec "$program" "$@"
