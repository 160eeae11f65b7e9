#!/bin/bash
# In the test VM (../shared/vmtest, with --udev and vimc): the device side of previsd.service,
# against a real kernel and udev. Checks, for every node previsd opens:
#  1. its /proc/devices class is one the unit's DeviceAllow= lets through, with the access needed;
#  2. after udev (Debian's rules plus ours, 60-previs-gpio.rules) it belongs to one of the unit's
#     SupplementaryGroups= with that access for the group;
#  3. a process with the unit's credentials opens it: a non-root uid with only those supplementary
#     groups, no capabilities, no_new_privs, inside a fresh user namespace where the groups are
#     unmapped (PrivateUsers=yes), and fails to without the groups (the probe is not vacuous).
# Not checked here (no systemd as PID 1 in the VM): the device cgroup program systemd builds from
# DeviceAllow=, and the mount namespace options. docs/systemd.md says what that leaves open.
# Usage: devices_vm.sh SOURCE_DIR. Exits 77 outside the VM.
set -euo pipefail
[ -n "${VMTEST:-}" ] || { echo "not in the test VM (VMTEST unset): skipped"; exit 77; }
src=$1
. "$src/tests/systemd/vm_box.sh"
unit=$src/systemd/previsd.service.in
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

allow=$(sed -n 's/^DeviceAllow=//p' "$unit")
groups=$(sed -n 's/^SupplementaryGroups=//p' "$unit")

# The group the unit's rule needs (systemd-sysusers creates it on the box), then our udev rule.
install_previs_udev_rule "$src"

gids=""
for g in $groups; do
    gid=$(getent group "$g" | cut -d: -f3) || { fail "group $g (SupplementaryGroups=) does not exist"; continue; }
    gids=${gids:+$gids,}$gid
done

# Name of a character major in /proc/devices.
class_of() {
    awk -v m="$1" '/^Character devices:/ {c = 1; next} /^Block devices:/ {c = 0}
                   c && $1 == m {print $2; exit}' /proc/devices
}

shopt -s nullglob
nodes=(/dev/video* /dev/media* /dev/dri/card* /dev/dri/renderD* /dev/gpiochip*)
checked=""
for node in "${nodes[@]}"; do
    access=rw
    major=$((16#$(stat -c %t "$node")))
    class=$(class_of "$major")
    # 1. the device cgroup
    if ! echo "$allow" | grep -Eq "^char-$class (rw|$access)m?$"; then
        fail "$node: class char-$class (major $major) is not in DeviceAllow= with '$access'"
    fi
    # 2. owner group and mode after udev
    group=$(stat -c %G "$node")
    mode=$(stat -c %a "$node")
    need=4; [ "$access" = rw ] && need=6
    if [ $(( 8#$mode & need )) -eq $need ]; then
        :  # open to everyone (e.g. renderD* 0666)
    elif ! echo " $groups " | grep -q " $group "; then
        fail "$node: group $group (mode $mode) is not one of SupplementaryGroups=$groups"
    elif [ $(( (8#$mode >> 3) & need )) -ne $need ]; then
        fail "$node: mode $mode does not give its group $group '$access'"
    fi
    checked="$checked $node:$access"
    echo "$node: char-$class, $group $mode, needs $access"
done
for want in /dev/video0 /dev/dri/card0 /dev/gpiochip0; do
    echo "$checked" | grep -q "$want:" || fail "$want missing in the VM"
done
ls /dev/media* >/dev/null 2>&1 || fail "no /dev/media* (vimc not loaded?)"

# 3. open as the service would. The probe opens every node, reporting each failure.
probe='
rc=0
for item in "$@"; do
    node=${item%:*}; access=${item##*:}
    # `true` with a redirection: the open and close, without risking the shell on failure.
    if [ "$access" = rw ]; then true 3<>"$node"; else true 3<"$node"; fi 2>/dev/null ||
        { echo "cannot open $node ($access)"; rc=1; }
done
exit $rc'
as_service() {
    setpriv --reuid=61234 --regid=61234 --groups="$1" --inh-caps=-all --bounding-set=-all \
        --no-new-privs -- unshare --user -- bash -c "$probe" probe $checked
}
if out=$(as_service "$gids" 2>&1); then
    echo "opened every node as uid 61234 with groups $groups (user namespace, no caps)"
else
    echo "$out"
    fail "the service's credentials cannot open its devices"
fi
# Without the supplementary groups every node must be refused, or the probe proves nothing.
out=$(as_service 61234 2>&1) || true
for item in $checked; do
    node=${item%:*}
    mode=$(stat -c %a "$node")
    # World-accessible nodes (e.g. renderD* 0666) are open to anyone: nothing to prove there.
    [ $(( (8#$mode) & 4 )) -ne 0 ] && continue
    echo "$out" | grep -q "cannot open $node " || fail "$node opens without the groups: probe is vacuous"
done

[ $failures -eq 0 ] || { echo "$failures failure(s)"; exit 1; }
echo "device access under the unit's credentials: OK"
