# Shared by scripts/container-test and scripts/compose-test (sourced, not run): the Docker
# client and a dockerd of our own, the Debian mirror of the apt sources, and the base image
# debian:bookworm without a registry (platform-notes.md). The sourcing script defines log,
# fail, skip, $engine, $cache, $work and $base_image before calling ensure_base_image.

# --- Docker client and engine ---------------------------------------------------------------
docker_cli=$(command -v docker 2>/dev/null || true)
if [[ -x /usr/bin/docker ]] && dpkg -S /usr/bin/docker >/dev/null 2>&1; then docker_cli=/usr/bin/docker; fi
docker() { DOCKER_BUILDKIT=1 "$docker_cli" "$@"; }
dockerd_pid=""
dockerd_log=""  # made by start_dockerd
start_dockerd() {  # a dockerd of our own when none answers (root, no systemd); stopped at exit
  [[ -n $docker_cli ]] && command -v dockerd >/dev/null 2>&1 && [[ $(id -u) == 0 ]] || return 1
  dockerd_log=$(mktemp "${TMPDIR:-/tmp}/hapco-dockerd.XXXXXX.log")
  log "no Docker engine answers: starting dockerd (log: $dockerd_log)"
  dockerd >"$dockerd_log" 2>&1 &
  dockerd_pid=$!
  local i
  for ((i = 0; i < 300; ++i)); do
    docker info >/dev/null 2>&1 && return 0
    kill -0 "$dockerd_pid" 2>/dev/null || break
    sleep 0.1
  done
  tail -20 "$dockerd_log" >&2
  kill -TERM "$dockerd_pid" 2>/dev/null; wait "$dockerd_pid" 2>/dev/null; dockerd_pid=""
  return 1
}
stop_dockerd() {
  [[ -n $dockerd_pid ]] || return 0
  kill -TERM "$dockerd_pid" 2>/dev/null
  local i
  for ((i = 0; i < 200; ++i)); do kill -0 "$dockerd_pid" 2>/dev/null || break; sleep 0.1; done
  kill -KILL "$dockerd_pid" 2>/dev/null
  wait "$dockerd_pid" 2>/dev/null || true
  dockerd_pid=""
}

# --- base image (without a registry) -------------------------------------------------------
# The Debian mirror the machine's apt sources name (deb822 .sources or one-line .list).
apt_mirror() {
  local uri
  uri=$(grep -hsE '^URIs:' /etc/apt/sources.list.d/*.sources 2>/dev/null | awk '{print $2}' | grep -m1 -E 'debian/?$' || true)
  [[ -n $uri ]] || uri=$(grep -hsE '^deb ' /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null |
    awk '{for (i = 2; i <= NF; ++i) if ($i ~ /^(https?|file):/) {print $i; exit}}' | grep -m1 -E 'debian/?$' || true)
  echo "${uri:-http://deb.debian.org/debian}"
}
engine_image_exists() {
  if [[ $engine == docker ]]; then docker image inspect "$1" >/dev/null 2>&1; else podman image exists "$1"; fi
}
ensure_base_image() {
  local local_tag=$base_image
  [[ $engine == docker ]] && local_tag=debian:bookworm  # what FROM debian:bookworm resolves to
  engine_image_exists "$local_tag" && return 0
  local tarball=$cache/debian-bookworm-minbase.tar
  if [[ ! -s $tarball ]]; then
    log "base image $base_image: trying the registry"
    if [[ $engine == docker ]]; then
      if timeout 60 "$docker_cli" pull -q "$local_tag" >/dev/null 2>&1; then return 0; fi
    elif timeout 60 podman pull -q "$base_image" >/dev/null 2>&1; then return 0; fi
    command -v debootstrap >/dev/null 2>&1 && [[ $(id -u) == 0 ]] ||
      skip "no $base_image: no registry answered, and making one needs debootstrap as root"
    local mirror
    mirror=$(apt_mirror)
    log "base image: debootstrap --variant=minbase bookworm from $mirror (once; cached in $cache)"
    mkdir -p "$cache"
    local rootfs=$cache/rootfs.tmp
    rm -rf "$rootfs"
    debootstrap --variant=minbase bookworm "$rootfs" "$mirror" >"$work/debootstrap.log" 2>&1 ||
      { tail -20 "$work/debootstrap.log"; fail "debootstrap failed"; }
    # Like the official image: no package lists or caches (the Dockerfile runs apt-get update).
    rm -rf "$rootfs"/var/cache/apt/*.bin "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/*
    tar -C "$rootfs" -cf "$tarball.tmp" . && mv "$tarball.tmp" "$tarball"
    rm -rf "$rootfs"
  fi
  log "base image: importing $tarball as $local_tag"
  if [[ $engine == docker ]]; then
    "$docker_cli" import - "$local_tag" <"$tarball" >/dev/null
  else
    podman import -q - "$base_image" <"$tarball" >/dev/null
  fi
}

