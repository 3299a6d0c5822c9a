# Helpers shared by tests/app/setup-chroot and tests/app/run (sourced, not run): where the chroot with
# the real Blender application lives, and the bind mounts a session inside it needs. Every mount made
# here is remembered and undone by app_umount.
APP_ROOT=${NUBIS_APP_ROOT:-/var/cache/nubis/blender-app}
APP_MOUNTS=()

app_mirror() {
  # The Debian mirror the host's own apt sources name (NUBIS_APP_MIRROR overrides it).
  if [ -n "${NUBIS_APP_MIRROR:-}" ]; then echo "$NUBIS_APP_MIRROR"; return; fi
  local m
  m=$(grep -hE '^(URIs:|deb )' /etc/apt/sources.list.d/*.sources /etc/apt/sources.list 2>/dev/null |
    grep -v security | grep -oE 'https?://[^ ]+' | head -1)
  if [ -z "$m" ]; then
    echo "nubis app: the host's apt sources name no Debian mirror; set NUBIS_APP_MIRROR to one" >&2
    return 1
  fi
  echo "$m"
}

app_mount() {
  local d
  for d in proc sys dev dev/pts dev/shm; do
    mkdir -p "$APP_ROOT/$d"
    mountpoint -q "$APP_ROOT/$d" && continue
    case $d in
      proc) mount -t proc proc "$APP_ROOT/proc" ;;
      sys) mount --rbind /sys "$APP_ROOT/sys" && mount --make-rslave "$APP_ROOT/sys" ;;
      *) mount --bind "/$d" "$APP_ROOT/$d" ;;
    esac || { echo "nubis app: mounting /$d into $APP_ROOT failed" >&2; return 1; }
    APP_MOUNTS+=("$APP_ROOT/$d")
  done
}

app_umount() {
  local i m
  for ((i = ${#APP_MOUNTS[@]} - 1; i >= 0; i--)); do
    m=${APP_MOUNTS[$i]}
    if [[ $m == */sys ]]; then umount -R "$m" 2>/dev/null || umount -lR "$m"; else umount "$m" 2>/dev/null || umount -l "$m"; fi
  done
  APP_MOUNTS=()
}

app_chroot() {
  # A command inside the chroot, with a clean environment (add variables with env VAR=... before it).
  chroot "$APP_ROOT" /usr/bin/env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    HOME=/root LANG=C.UTF-8 TERM=dumb DEBIAN_FRONTEND=noninteractive "$@"
}
