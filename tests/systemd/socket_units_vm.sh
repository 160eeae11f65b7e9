#!/bin/bash
# In the test VM: the socket units `previsd --network-units` writes, under the real systemd 252
# (PID 1 of a fresh PID and mount namespace, as sandbox_vm.sh runs it), with the installed
# previsd.service and a drop-in that only stands a shell command in for previsd (it counts its
# starts, and exits 2 when told to). Checks (issue 52): a [web] listen address that is not up yet
# does not keep previsd from starting (FreeBind=); after `systemctl stop previsd` and after an
# exit 2 (a config error) a packet on its socket does not start it again (BindsTo=); `systemctl
# start previsd` brings it and its sockets back.
# Usage: socket_units_vm.sh SOURCE_DIR PREVISD_BINARY. Exits 77 outside the VM.
set -euo pipefail
[ -n "${VMTEST:-}" ] || { echo "not in the test VM (VMTEST unset): skipped"; exit 77; }
src=$1
previsd=$2
work=$(mktemp -d /tmp/previs_socket_units.XXXXXX)
trap 'rm -rf "$work"' EXIT

demo=$src/examples/demo
# FreeD in on loopback (a packet the test can send), the page on an address no interface has.
cat >"$work/previsd.toml" <<EOT
version = 1
scene = "$demo/previs.toml"
[cameras.scene]
source = "session"
device = "$demo/session/cameras/scene"
width = 640
height = 360
calibration = "$demo/scene_camera.yaml"
[tracking]
board = "$demo/board.toml"
listen = "127.0.0.1:47123"
[web]
listen = "192.0.2.77:47124"
EOT
mkdir -p "$work/units"
"$previsd" --config "$work/previsd.toml" --network-units "$work/units" >/dev/null

cat >"$work/inside.sh" <<EOT
#!/bin/bash
# A private /run and unit folder: nothing of the host's systemd is seen or touched.
mount -t tmpfs tmpfs /run
mount -t tmpfs tmpfs /etc/systemd/system
cp -r "$work/units/." /etc/systemd/system/
. "$src/tests/systemd/vm_box.sh"
install_previsd_unit "$src"
cat >/etc/systemd/system/previsd.service.d/standin.conf <<'EOF'
[Unit]
DefaultDependencies=no
OnFailure=
[Service]
Type=simple
WatchdogSec=0
RestartSec=1
SupplementaryGroups=
ExecReload=
ExecStart=
ExecStart=/bin/sh -c 'echo start; if [ -e /run/previs-exit2 ]; then exit 2; fi; exec sleep 600'
StandardOutput=append:/run/previs-starts.log
EOF
for s in /etc/systemd/system/previsd-*.socket; do
    mkdir -p "\$s.d"
    printf '[Unit]\nDefaultDependencies=no\n' >"\$s.d/test.conf"
done
{ manager_ending_oneshot_head; cat <<'EOF'; } >/etc/systemd/system/driver.service
ExecStart=$work/driver.sh
StandardOutput=truncate:$work/driver.log
StandardError=inherit
EOF
exec /lib/systemd/systemd --system --unit=driver.service --log-target=console --log-level=info
EOT
cat >"$work/driver.sh" <<'EOT'
#!/bin/bash
set -u
starts() { cat /run/previs-starts.log 2>/dev/null | grep -c '^start$' || true; }
# Type=simple: systemctl returns before the command has run; wait (at most 10 s) for N starts.
starts_reach() {
    for _ in $(seq 100); do [ "$(starts)" -ge "$1" ] && break; sleep 0.1; done
    [ "$(starts)" = "$1" ]
}
packet() {
    python3 -c 'import socket; socket.socket(socket.AF_INET, socket.SOCK_DGRAM).sendto(b"x", ("127.0.0.1", 47123))'
    sleep 2
}
fail() { echo "FAIL: $*"; systemctl status --no-pager previsd.service previsd-web.socket || true; exit 1; }
systemctl start previsd.service || fail "previsd did not start (web on an address not up yet)"
starts_reach 1 || fail "started $(starts) times, not once"
echo "ok   previsd starts with [web] listen on an address no interface has yet"
systemctl stop previsd.service
packet
[ "$(starts)" = 1 ] || fail "a packet started the previsd an operator stopped"
systemctl is-active --quiet previsd-freed-in.socket && fail "its socket still listens"
echo "ok   stopped stays stopped: a packet does not start it"
systemctl start previsd.service && starts_reach 2 || fail "systemctl start did not bring it back"
systemctl is-active --quiet previsd-freed-in.socket || fail "its socket did not come back"
echo "ok   systemctl start previsd brings it and its sockets back"
# A crash is restarted, sockets and all: the socket units follow it through.
systemctl kill --signal=SIGKILL previsd.service
starts_reach 3 && systemctl is-active --quiet previsd.service || fail "a crash was not restarted"
systemctl is-active --quiet previsd-freed-in.socket || fail "its socket did not come back after a crash"
echo "ok   a crash is restarted with its sockets"
touch /run/previs-exit2
systemctl restart previsd.service || true
sleep 2
[ "$(systemctl show -P ExecMainStatus previsd.service)" = 2 ] || fail "the stand-in did not exit 2"
packet
[ "$(starts)" = 4 ] || fail "after exit 2 a packet started it again ($(starts) starts)"
echo "ok   exit 2 stays failed: a packet does not start it"
EOT
chmod 755 "$work/inside.sh" "$work/driver.sh"
status=0
container=vmtest timeout 120 unshare --pid --mount --fork --mount-proc "$work/inside.sh" \
    </dev/null >"$work/manager.log" 2>&1 || status=$?
cat "$work/driver.log" 2>/dev/null || true
if [ $status -ne 0 ] || ! grep -q "exit 2 stays failed" "$work/driver.log"; then
    echo "--- manager log"; tail -60 "$work/manager.log"
    echo "FAIL: the socket units (manager exited $status)"
    exit 1
fi
echo "socket units: FreeBind= and BindsTo= hold under systemd: OK"
