#!/usr/bin/env bash
# Run a command in a Debian 13 (trixie) root on this machine, on a copy of this repository.
#
#   scripts/trixie-root.sh ./test.sh            # the test suite under Debian 13 (dolfinx 0.9)
#   scripts/trixie-root.sh ./demo.sh [ARGS]     # the demo; its output stays in the root (path printed)
#   scripts/trixie-root.sh .venv/bin/python -c 'import dolfinx; print(dolfinx.__version__)'
#   scripts/trixie-root.sh                      # an interactive shell in the copy
#   CFCONTACT_ROOT_SUITE=bookworm scripts/trixie-root.sh ./test.sh   # the same in a fresh Debian 12
#
# First use creates the root with `debootstrap --variant=minbase trixie` (a minute or two),
# from the Debian mirror this host's apt already uses; later runs reuse it. Each run:
#   1. copies the current work tree (without .git, .venv, caches, output/) to /root/cfcontact
#      inside the root; the root's .venv there is kept between runs,
#   2. mounts /proc, /sys and /dev (bind) in a private mount and PID namespace (unshare), so the
#      mounts and any process left behind (Xvfb, mpirun) vanish when the command ends; where
#      unshare is unavailable it mounts in place and unmounts on exit (trap),
#   3. runs scripts/install.sh there (seconds once installed; set CFCONTACT_NO_INSTALL=1 to skip),
#   4. runs the command in /root/cfcontact with a clean environment and returns its exit status.
#
# Environment:
#   CFCONTACT_ROOT_SUITE     trixie (default) or bookworm: a fresh Debian 12 root, where
#                            scripts/install.sh installs everything from nothing (the README's
#                            "fresh machine"); the host's own CA certificates are copied in
#   CFCONTACT_TRIXIE_ROOT    where the root lives (default /var/cache/cfcontact/<suite>)
#   CFCONTACT_CHROOT_WORKDIR where the copy goes inside the root (default /root/cfcontact);
#                            runs on the same workdir are serialised with a lock, so give
#                            concurrent users different workdirs
#   CFCONTACT_DEBIAN_MIRROR  Debian mirror URL (default: the one in /etc/apt/sources.list*)
#   CFCONTACT_NO_INSTALL=1   do not run scripts/install.sh before the command (./test.sh and
#                            ./demo.sh run it themselves)
#   CFCONTACT_NO_UNSHARE=1   mount in place (unmounted on exit) instead of in a namespace
# Passed into the root: CI, TERM, PYTEST_ADDOPTS, CFCONTACT_*, OMPI_*, HYPOTHESIS_*.
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
SUITE=${CFCONTACT_ROOT_SUITE:-trixie}
case "$SUITE" in
    trixie) LABEL="Debian 13" ;;
    bookworm) LABEL="Debian 12" ;;
    *) printf '[trixie-root] error: CFCONTACT_ROOT_SUITE must be trixie or bookworm, got %s\n' "$SUITE" >&2; exit 1 ;;
esac
ROOT=${CFCONTACT_TRIXIE_ROOT:-/var/cache/cfcontact/$SUITE}
WORK=${CFCONTACT_CHROOT_WORKDIR:-/root/cfcontact}

say() { printf '[trixie-root] %s\n' "$*" >&2; }
die() { say "error: $*"; exit 1; }

if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || die "must run as root (no sudo found)"
    exec sudo --preserve-env=CI,TERM,PYTEST_ADDOPTS,CFCONTACT_ROOT_SUITE,CFCONTACT_TRIXIE_ROOT,CFCONTACT_CHROOT_WORKDIR,CFCONTACT_DEBIAN_MIRROR,CFCONTACT_NO_INSTALL \
        "$0" "$@"
fi
case "$ROOT" in /?*) ;; *) die "CFCONTACT_TRIXIE_ROOT must be an absolute path: $ROOT" ;; esac
case "$WORK" in /?*) ;; *) die "CFCONTACT_CHROOT_WORKDIR must be an absolute path: $WORK" ;; esac
ROOT=${ROOT%/}
WORK=${WORK%/}

# ---------------------------------------------------------------------------------------------
# Mirror: reuse the Debian archive URL configured for this host's apt (deb822 or one-line form).
apt_uri_for_suite() {   # $1 = exact suite name, prints the first matching URI
    local files=()
    [ -f /etc/apt/sources.list ] && files+=(/etc/apt/sources.list)
    for f in /etc/apt/sources.list.d/*.list /etc/apt/sources.list.d/*.sources; do
        [ -f "$f" ] && files+=("$f")
    done
    [ ${#files[@]} -gt 0 ] || return 0
    awk -v want="$1" '
        function flush() {
            if (done) return
            if (types ~ /(^|[ \t])deb([ \t]|$)/ && uris != "") {
                n = split(suites, s, /[ \t]+/)
                for (i = 1; i <= n; i++) if (s[i] == want) { split(uris, u, /[ \t]+/); print u[1]; done = 1; exit }
            }
            types = ""; uris = ""; suites = ""
        }
        FNR == 1 { flush() }
        /^[ \t]*#/ { next }
        /^[ \t]*$/ { flush(); next }
        /^Types:/  { sub(/^Types:[ \t]*/, "");  types = $0;  next }
        /^URIs:/   { sub(/^URIs:[ \t]*/, "");   uris = $0;   next }
        /^Suites:/ { sub(/^Suites:[ \t]*/, ""); suites = $0; next }
        /^deb[ \t]/ {
            # one-line form: deb [opts] URI suite components...
            line = $0; sub(/^deb[ \t]+/, "", line)
            if (line ~ /^\[/) sub(/^\[[^]]*\][ \t]*/, "", line)
            split(line, f, /[ \t]+/)
            if (f[2] == want) { print f[1]; done = 1; exit }
        }
        END { flush() }
    ' "${files[@]}"
}

host_codename() { ( . /etc/os-release 2>/dev/null; echo "${VERSION_CODENAME:-}" ); }

pick_mirror() {
    local hc uri
    if [ -n "${CFCONTACT_DEBIAN_MIRROR:-}" ]; then echo "$CFCONTACT_DEBIAN_MIRROR"; return; fi
    hc=$(host_codename)
    for s in "$hc" "$SUITE"; do
        [ -n "$s" ] || continue
        uri=$(apt_uri_for_suite "$s")
        if [ -n "$uri" ]; then echo "${uri%/}"; return; fi
    done
    die "no Debian mirror found in /etc/apt/sources.list*; set CFCONTACT_DEBIAN_MIRROR=<url>"
}

pick_security_mirror() {   # may print nothing
    local hc uri
    hc=$(host_codename)
    for s in "$hc-security" "$SUITE-security"; do
        uri=$(apt_uri_for_suite "$s")
        if [ -n "$uri" ]; then echo "${uri%/}"; return; fi
    done
}

# ---------------------------------------------------------------------------------------------
mkdir -p "$(dirname "$ROOT")"
LOCKDIR=$(dirname "$ROOT")

# Refuse to delete anything that has a mount below it (belt and braces: our mounts are private).
has_mounts_below() { awk -v p="$1/" 'index($5 "/", p) == 1 { found = 1 } END { exit !found }' /proc/self/mountinfo; }

create_root() {
    local mirror sec partial="$ROOT.partial"
    mirror=$(pick_mirror)
    sec=$(pick_security_mirror)
    if ! command -v debootstrap >/dev/null; then
        say "installing debootstrap"
        apt-get update -qq || true
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
    fi
    if [ -e "$partial" ]; then
        has_mounts_below "$partial" && die "$partial has mounts below it; unmount them first"
        rm -rf --one-file-system "$partial"
    fi
    say "creating $LABEL root at $ROOT from $mirror (debootstrap --variant=minbase, ~1-2 min)"
    local keyring=()
    [ -f /usr/share/keyrings/debian-archive-keyring.gpg ] &&
        keyring=(--keyring=/usr/share/keyrings/debian-archive-keyring.gpg)
    local t0=$SECONDS
    # debootstrap mounts /proc and /sys in the target itself: keep those mounts private.
    if unshare --mount --propagation private true 2>/dev/null; then
        unshare --mount --propagation private -- \
            debootstrap --variant=minbase "${keyring[@]}" "$SUITE" "$partial" "$mirror" \
            >"$LOCKDIR/debootstrap.log" 2>&1 || { tail -n 30 "$LOCKDIR/debootstrap.log" >&2; die "debootstrap failed (log: $LOCKDIR/debootstrap.log)"; }
    else
        debootstrap --variant=minbase "${keyring[@]}" "$SUITE" "$partial" "$mirror" \
            >"$LOCKDIR/debootstrap.log" 2>&1 || { tail -n 30 "$LOCKDIR/debootstrap.log" >&2; die "debootstrap failed (log: $LOCKDIR/debootstrap.log)"; }
    fi
    # apt sources like a debian:$SUITE image: main, updates and (if the host has one) security.
    rm -f "$partial/etc/apt/sources.list"
    {
        printf 'Types: deb\nURIs: %s\nSuites: %s %s-updates\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
            "$mirror" "$SUITE" "$SUITE"
        if [ -n "$sec" ]; then
            printf '\nTypes: deb\nURIs: %s\nSuites: %s-security\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
                "$sec" "$SUITE"
        fi
    } >"$partial/etc/apt/sources.list.d/debian.sources"
    # Same release-file date policy as the host's apt (matters for snapshot mirrors).
    apt-config dump 2>/dev/null | grep -E '^Acquire::Check-(Valid-Until|Date) ' \
        >"$partial/etc/apt/apt.conf.d/90cfcontact-host" || true
    # No daemons start inside the root.
    printf '#!/bin/sh\nexit 101\n' >"$partial/usr/sbin/policy-rc.d"
    chmod 755 "$partial/usr/sbin/policy-rc.d"
    echo "$SUITE $(date -u +%FT%TZ) $mirror" >"$partial/.cfcontact-root"
    mv "$partial" "$ROOT"
    say "root created in $((SECONDS - t0)) s"
}

# Create the root once (global lock: concurrent first uses wait for one debootstrap).
exec 8>"$LOCKDIR/$SUITE.create.lock"
if [ ! -f "$ROOT/.cfcontact-root" ]; then
    flock -n 8 || { say "waiting for another run creating the root..."; flock 8; }
    if [ ! -f "$ROOT/.cfcontact-root" ]; then
        if [ -e "$ROOT" ]; then die "$ROOT exists but is not a finished root; remove it and retry"; fi
        create_root
    fi
    flock -u 8
fi
exec 8>&-

# One run per workdir at a time.
exec 9>"$LOCKDIR/$SUITE$(echo "$WORK" | tr / _).lock"
flock -n 9 || { say "waiting for another run using $WORK in the root..."; flock 9; }

# ---------------------------------------------------------------------------------------------
# Copy the work tree (keep the root's .venv).
DST="$ROOT$WORK"
mkdir -p "$DST"
find "$DST" -mindepth 1 -maxdepth 1 ! -name .venv -exec rm -rf --one-file-system {} +
tar -C "$REPO" \
    --exclude=./.venv --exclude=./.git --exclude=./output --exclude=__pycache__ \
    --exclude=.pytest_cache --exclude=.hypothesis --exclude='*.egg-info' \
    -cf - . | tar -C "$DST" -xf -
cp -L /etc/resolv.conf "$ROOT/etc/resolv.conf" 2>/dev/null || true
# The host's own CA certificates (a proxy's, say): pip in the root reaches what the host reaches.
# Debian's ca-certificates takes them in when install.sh installs it, or here once it is there.
if compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
    mkdir -p "$ROOT/usr/local/share/ca-certificates"
    new=0
    for crt in /usr/local/share/ca-certificates/*.crt; do
        cmp -s "$crt" "$ROOT/usr/local/share/ca-certificates/${crt##*/}" || { cp "$crt" "$ROOT/usr/local/share/ca-certificates/"; new=1; }
    done
    if [ "$new" = 1 ] && [ -x "$ROOT/usr/sbin/update-ca-certificates" ]; then
        chroot "$ROOT" /usr/sbin/update-ca-certificates >/dev/null 2>&1 || true
    fi
fi
[ -f /etc/hosts ] && cp /etc/hosts "$ROOT/etc/hosts"

# Clean environment for the command inside.
ENVV=(HOME=/root USER=root LOGNAME=root SHELL=/bin/bash LANG=C.UTF-8 LC_ALL=C.UTF-8
      PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
      DEBIAN_FRONTEND=noninteractive TERM="${TERM:-dumb}")
while IFS='=' read -r name _; do
    case "$name" in
        CI|PYTEST_ADDOPTS|CFCONTACT_*|OMPI_*|HYPOTHESIS_*) ENVV+=("$name=${!name}") ;;
    esac
done < <(env)

[ $# -gt 0 ] || set -- bash -l
case "$1" in ./test.sh|test.sh|./demo.sh|demo.sh) ENVV+=(CFCONTACT_NO_INSTALL=1) ;; esac  # they install
INNER='cd "$0" || exit 1
if [ "${CFCONTACT_NO_INSTALL:-}" != 1 ] && [ -x scripts/install.sh ]; then
    scripts/install.sh || exit $?
fi
"$@"'

say "running in $LABEL root ($ROOT), in $WORK: $*"
MOUNTED_HERE=0
cleanup() {
    if [ "$MOUNTED_HERE" = 1 ]; then
        for m in dev sys proc; do
            umount -R "$ROOT/$m" 2>/dev/null || umount -lR "$ROOT/$m" 2>/dev/null || true
        done
    fi
}
trap cleanup EXIT

rc=0
if [ "${CFCONTACT_NO_UNSHARE:-}" != 1 ] && unshare --mount --propagation private true 2>/dev/null; then
    # Private mount + PID namespace: mounts and stray processes end with the command.
    unshare --mount --pid --fork --kill-child --propagation private -- /bin/bash -c '
        R=$1; W=$2; I=$3; n=$4; shift 4
        envv=("${@:1:n}"); shift "$n"
        mount -t proc proc "$R/proc" &&
        mount --rbind /sys "$R/sys" &&
        mount --rbind /dev "$R/dev" || exit 125
        chroot "$R" /usr/bin/env -i "${envv[@]}" /bin/bash -c "$I" "$W" "$@"
    ' bash "$ROOT" "$WORK" "$INNER" "${#ENVV[@]}" "${ENVV[@]}" "$@" || rc=$?
else
    for m in proc sys dev; do
        if ! mountpoint -q "$ROOT/$m"; then
            MOUNTED_HERE=1
            case $m in
                proc) mount -t proc proc "$ROOT/proc" ;;
                *) mount --rbind "/$m" "$ROOT/$m"; mount --make-rslave "$ROOT/$m" ;;
            esac
        fi
    done
    chroot "$ROOT" /usr/bin/env -i "${ENVV[@]}" /bin/bash -c "$INNER" "$WORK" "$@" || rc=$?
fi
[ -d "$DST/output" ] && say "files the command wrote under output/ are in $DST/output"
exit "$rc"
