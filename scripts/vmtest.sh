#!/usr/bin/env bash
# Runs ../shared/vmtest on a Debian kernel whose packages the archive holds at one version.
# usage: scripts/vmtest.sh VMTEST [vmtest arguments...]
#
# vmtest downloads the kernel image, headers, kbuild and source at the version of
# linux-image-amd64's candidate. Debian's security archive sometimes publishes a rebuilt kbuild
# or source without the matching image (in November 2026: linux-kbuild-6.1 only at 6.1.192-3,
# the image at 6.1.192-2), and then every VM test fails before it boots. Where the candidate's
# set is incomplete, this pins the kernel package, for vmtest's apt calls only (APT_CONFIG), to
# the newest version the archive holds complete. Where it is complete, vmtest runs unchanged.
set -euo pipefail
vmtest=${1:?usage: scripts/vmtest.sh VMTEST [vmtest arguments...]}
shift
kpkg=${VMTEST_KERNEL_PKG:-linux-image-amd64}

versions() { apt-cache madison "$1" 2>/dev/null | awk -F'|' '{gsub(/ /, "", $2); print $2}'; }
candidate() { apt-cache policy "$1" 2>/dev/null | awk '/Candidate:/ {print $2}'; }

# True when every package vmtest downloads for kernel package version $1 is in the archive.
complete() {
    local ver=$1 abi kv mm pkg
    abi=$(apt-cache depends "$kpkg=$ver" 2>/dev/null | awk '/Depends: linux-image-/ {print $2; exit}')
    [[ -n $abi ]] || return 1
    kv=${abi#linux-image-}
    mm=$(cut -d. -f1,2 <<<"$ver")
    for pkg in "$abi" "linux-headers-$kv" "linux-headers-${kv%-*}-common" "linux-kbuild-$mm" \
        "linux-source-$mm"; do
        versions "$pkg" | grep -qxF -- "$ver" || return 1
    done
}

current=$(candidate "$kpkg")
if [[ -n $current && $current != "(none)" ]] && ! complete "$current"; then
    pinned=""
    for ver in $(versions "$kpkg"); do
        if complete "$ver"; then
            pinned=$ver
            break
        fi
    done
    if [[ -n $pinned ]]; then
        dir=$(mktemp -d "${TMPDIR:-/tmp}/vmtest-apt.XXXXXX")
        trap 'rm -rf "$dir"' EXIT
        printf 'Package: %s\nPin: version %s\nPin-Priority: 1001\n' "$kpkg" "$pinned" \
            >"$dir/preferences"
        printf 'Dir::Etc::Preferences "%s";\n' "$dir/preferences" >"$dir/apt.conf"
        export APT_CONFIG=$dir/apt.conf
        echo "vmtest.sh: the archive lacks part of $kpkg $current's kernel packages;" \
            "using $pinned" >&2
        # Not exec: the trap removes the pin's folder when vmtest ends.
        "$vmtest" "$@"
        exit
    fi
fi
exec "$vmtest" "$@"
