#!/bin/sh
# Checks of the installed previsd.service (tests/systemd/CMakeLists.txt registers one CTest per
# mode). Usage: unit_check.sh install|verify|security|devices BUILD_DIR [PREVISD_BINARY
# [PREVIS_BINARY]]
# Each mode installs the previs-systemd component into a scratch folder first, so what is checked
# is the unit as `cmake --install` writes it.
set -eu
mode=$1
build=$2
previsd=${3:-}
previs=${4:-}
max_exposure=0.5

tmp=$(mktemp -d /tmp/previs_unit.XXXXXX)
trap 'rm -rf "$tmp"' EXIT

fail() { echo "FAIL: $*" >&2; exit 1; }

# Prefix = the scratch folder: ExecStart and the config then point into it, so they exist.
cmake --install "$build" --component previs-systemd --prefix "$tmp" >"$tmp/install.log" ||
    { cat "$tmp/install.log"; fail "cmake --install failed"; }
unit=$tmp/lib/systemd/system/previsd.service
[ -f "$unit" ] || fail "cmake --install did not write $unit"

# Values of KEY= in the unit (one per line, in order).
values() { sed -n "s/^$1=//p" "$unit"; }

# systemd-analyze's exposure score of unit $1, at most $2.
check_exposure() {
    out=$(systemd-analyze security --offline=true --no-pager "$1" 2>&1) ||
        { echo "$out"; fail "systemd-analyze security failed"; }
    echo "$out" | grep '✗' || true
    level=$(echo "$out" | sed -n 's/.*Overall exposure level for previsd.service: \([0-9.]*\).*/\1/p')
    [ -n "$level" ] || { echo "$out"; fail "no 'Overall exposure level' line"; }
    echo "exposure: $level (limit $2)"
    awk -v l="$level" -v m="$2" 'BEGIN { exit !(l <= m) }' || fail "exposure $level is above $2"
}

case $mode in
install)
    # The paths written into the unit follow the install prefix.
    [ "$(values ExecStart)" = "$tmp/bin/previsd --config $tmp/etc/previs/previsd.toml" ] ||
        fail "ExecStart is '$(values ExecStart)'"
    for f in previsd.toml board.toml scene_camera.yaml fisheye.yaml; do
        [ -f "$tmp/etc/previs/$f" ] || fail "example config $f not installed in $tmp/etc/previs"
    done
    [ -f "$tmp/lib/udev/rules.d/60-previs-gpio.rules" ] || fail "udev rule not installed"
    [ -f "$tmp/lib/sysusers.d/previs.conf" ] || fail "sysusers.d file not installed"
    for f in previsd-retry.timer previsd-retry.service; do
        [ -f "$tmp/lib/systemd/system/$f" ] || fail "$f not installed beside the unit"
    done
    [ "$(values OnFailure)" = "previsd-retry.timer" ] || fail "OnFailure= is '$(values OnFailure)'"
    [ "$(values ExecReload)" = "$tmp/bin/previs ctl reload" ] ||
        fail "ExecReload is '$(values ExecReload)'"
    # An operator's edited config survives a reinstall.
    echo "# edited" >"$tmp/etc/previs/previsd.toml"
    cmake --install "$build" --component previs-systemd --prefix "$tmp" >/dev/null
    [ "$(cat "$tmp/etc/previs/previsd.toml")" = "# edited" ] || fail "reinstall overwrote the config"
    # The box's layout: --prefix /usr reads its config from /etc (under DESTDIR here).
    DESTDIR=$tmp/destdir cmake --install "$build" --component previs-systemd --prefix /usr >/dev/null
    # Installed paths relative to the DESTDIR root.
    unit_rel=usr/lib/systemd/system/previsd.service
    config_rel=etc/previs/previsd.toml
    u=$tmp/destdir/$unit_rel
    [ "$(sed -n 's/^ExecStart=//p' "$u")" = "/usr/bin/previsd --config /$config_rel" ] ||
        fail "with --prefix /usr, ExecStart is '$(sed -n 's/^ExecStart=//p' "$u")'"
    [ -f "$tmp/destdir/$config_rel" ] || fail "with --prefix /usr, no $config_rel under the install root"
    echo "install layout OK"
    ;;
verify)
    mkdir -p "$tmp/bin"
    # The unit's executables (ExecStart= previsd, ExecReload= previs): the built ones when given;
    # else a stub, since verify needs an executable there and any will do.
    for pair in "previsd:$previsd" "previs:$previs"; do
        name=${pair%%:*} binary=${pair#*:}
        if [ -n "$binary" ] && [ -x "$binary" ]; then
            cp "$binary" "$tmp/bin/$name"
        else
            printf '#!/bin/sh\nexit 1\n' >"$tmp/bin/$name"
            chmod +x "$tmp/bin/$name"
            echo "note: no $name binary given, a stub stands in the unit"
        fi
    done
    # verify exits 0 on mere warnings (unknown keys, bad values): any line naming the unit fails.
    # The retry units are checked beside it (OnFailure= names the timer, the timer the service).
    status=0
    out=$(systemd-analyze verify --man=no --generators=no "$unit" \
        "$tmp/lib/systemd/system/previsd-retry.timer" \
        "$tmp/lib/systemd/system/previsd-retry.service" 2>&1) || status=$?
    [ -n "$out" ] && echo "$out"
    [ $status -eq 0 ] || fail "systemd-analyze verify exited $status"
    if echo "$out" | grep -q previsd; then fail "systemd-analyze verify warns about the unit"; fi
    echo "systemd-analyze verify: no warnings"
    ;;
security-network)
    # Every network feature on: the units previsd writes for that config. The service keeps
    # its sandbox (systemd makes the sockets), so its exposure stays as without the network;
    # the socket units pass `systemd-analyze verify`.
    [ -n "$previsd" ] && [ -x "$previsd" ] || { echo "SKIP: no previsd binary given"; exit 77; }
    conf=$tmp/etc/previs/previsd.toml
    grep -q '^\[web\]' "$conf" || printf '\n[web]\nlisten = "0.0.0.0:8080"\n' >>"$conf"
    printf '\n[freed]\nout = "127.0.0.1:40000"\n\n[opentrackio]\nout = "multicast"\n' >>"$conf"
    echo "a-test-token-of-24-chars" >"$tmp/etc/previs/web-token"
    units=$tmp/etc/systemd/system
    "$previsd" --config "$conf" --network-units "$units" || fail "previsd --network-units failed"
    dropin=$units/previsd.service.d/network.conf
    cat "$dropin" "$units"/previsd-*.socket
    for line in "Sockets=previsd-freed.socket previsd-opentrackio.socket previsd-web.socket" \
        "LoadCredential=web-token:$tmp/etc/previs/web-token"; do
        grep -qxF "$line" "$dropin" || fail "the drop-in lacks '$line'"
    done
    grep -qx 'IPAddressAllow=127.0.0.1' "$units/previsd-freed.socket" ||
        fail "FreeD's socket is not limited to its destination"
    grep -qx 'IPAddressAllow=239.135.1.1' "$units/previsd-opentrackio.socket" ||
        fail "OpenTrackIO's socket is not limited to its group"
    grep -qx 'ListenStream=0.0.0.0:8080' "$units/previsd-web.socket" || fail "no web socket"
    # A packet never starts a previsd that was stopped or exited 2; an address not up yet binds.
    for s in "$units"/previsd-*.socket; do
        grep -qx 'BindsTo=previsd.service' "$s" || fail "$s does not live and die with previsd"
        grep -qx 'FreeBind=yes' "$s" || fail "$s cannot bind an address that is not up yet"
    done
    mkdir -p "$tmp/merged"
    cat "$unit" "$dropin" >"$tmp/merged/previsd.service"
    sed -i "s#^ExecStart=.*#ExecStart=/bin/true#; s#^ExecReload=.*#ExecReload=/bin/true#" \
        "$tmp/merged/previsd.service"
    cp "$units"/previsd-*.socket "$tmp/merged/"
    out=$(cd "$tmp/merged" && systemd-analyze verify --man=no --generators=no ./previsd.service \
        ./previsd-web.socket ./previsd-freed.socket ./previsd-opentrackio.socket 2>&1) ||
        { echo "$out"; fail "systemd-analyze verify of the network units failed"; }
    if echo "$out" | grep -q previsd; then echo "$out"; fail "verify warns about the units"; fi
    check_exposure "$tmp/merged/previsd.service" "$max_exposure"
    ;;
security)
    check_exposure "$unit" "$max_exposure"
    ;;
devices)
    # Every device class previsd opens is let through the device cgroup with the access it needs,
    # and /dev is the real one. (The VM test devices_vm.sh checks the names against a kernel.)
    [ "$(values PrivateDevices)" = "no" ] || fail "PrivateDevices= must be no (it hides /dev/video*)"
    policy=$(values DevicePolicy)
    [ "$policy" = "closed" ] || fail "DevicePolicy= is '$policy', expected closed"
    allow=$(values DeviceAllow)
    for need in "char-video4linux rw" "char-media rw" "char-drm rw" "char-gpiochip rw"; do
        echo "$allow" | grep -qx "$need" || fail "no 'DeviceAllow=$need'"
    done
    # Nothing previsd does not open: no input devices (keyboards), no group that reaches them.
    [ "$(echo "$allow" | wc -l)" -eq 4 ] || fail "DeviceAllow= lets through more than previsd opens: $allow"
    groups=$(values SupplementaryGroups)
    [ "$groups" = "video render previs" ] ||
        fail "SupplementaryGroups= is '$groups', not video render previs (input reaches keyboards)"
    rule=$tmp/lib/udev/rules.d/60-previs-gpio.rules
    grep -q 'KERNEL=="gpiochip\*".*GROUP="previs"' "$rule" || fail "$rule does not give gpiochip* to previs"
    grep -qx 'g previs -' "$tmp/lib/sysusers.d/previs.conf" || fail "sysusers.d does not create group previs"
    # Bounded memory and tasks, sized in the unit's comment from the measured peak.
    [ "$(values MemoryMax)" = "4G" ] || fail "MemoryMax= is '$(values MemoryMax)', not 4G"
    [ "$(values TasksMax)" = "512" ] || fail "TasksMax= is '$(values TasksMax)', not 512"
    # Descriptors for the cameras and a take whatever the network does (issue 52).
    [ "$(values LimitNOFILE)" = "16384" ] || fail "LimitNOFILE= is '$(values LimitNOFILE)', not 16384"
    # Settings that would cut previsd off its devices or its JIT.
    [ "$(values MemoryDenyWriteExecute)" != "yes" ] || fail "MemoryDenyWriteExecute=yes breaks llvmpipe"
    echo "device access settings OK"
    ;;
*)
    fail "unknown mode $mode"
    ;;
esac
