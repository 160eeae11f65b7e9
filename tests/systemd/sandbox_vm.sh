#!/bin/bash
# In the test VM (../shared/vmtest with --udev and vimc): previsd.service's real sandbox, applied
# by the real systemd. systemd runs as PID 1 of a fresh PID namespace (the VM's init is busybox),
# with the unit plus a drop-in that only swaps ExecStart for sandbox_probe (and Type=oneshot, exit
# the manager afterwards). The probe streams from a camera, queries the media device, becomes DRM
# master, requests a GPIO line, and checks that the device cgroup refuses devices DeviceAllow= does
# not list (an input device, uinput). Then `vulkaninfo --summary` runs under the same sandbox.
# Given PREVISD_BINARY, the socket units' checks (socket_units_vm.sh) run last, in the same boot.
# Usage: sandbox_vm.sh SOURCE_DIR PROBE_BINARY [PREVISD_BINARY]. Exits 77 outside the VM.
set -euo pipefail
[ -n "${VMTEST:-}" ] || { echo "not in the test VM (VMTEST unset): skipped"; exit 77; }
src=$1
. "$src/tests/systemd/vm_box.sh"
probe=$2
previsd=${3:-}

# What the box has after `cmake --install --prefix /usr` and systemd-sysusers: group previs and
# the udev rule.
install_previs_udev_rule "$src"
# Nodes whose file mode lets anyone in: only the device cgroup can refuse them.
chmod 0666 /dev/uinput /dev/input/event0

# PrivateTmp= hides /tmp and the build tree may be unreadable for the dynamic user: /usr/local.
install -m 755 "$probe" /usr/local/bin/previs-sandbox-probe
cat >/usr/local/bin/previs-sandbox-check <<'EOT'
#!/bin/sh
echo "running as: $(id)"
/usr/local/bin/previs-sandbox-probe || exit 1
# The Vulkan loader reads /usr/share/vulkan, lavapipe initialises; Mesa's cache dir is writable.
vulkaninfo --summary 2>&1 | grep -E "deviceName|driverName" || { echo "FAIL vulkaninfo"; exit 1; }
echo "ok   vulkaninfo under the sandbox"
touch "$MESA_SHADER_CACHE_DIR/probe" && echo "ok   $MESA_SHADER_CACHE_DIR writable" ||
    { echo "FAIL $MESA_SHADER_CACHE_DIR not writable"; exit 1; }
mkdir -p "$PREVIS_SHADER_CACHE_DIR" && touch "$PREVIS_SHADER_CACHE_DIR/probe" &&
    echo "ok   $PREVIS_SHADER_CACHE_DIR writable" ||
    { echo "FAIL $PREVIS_SHADER_CACHE_DIR not writable"; exit 1; }
EOT
chmod 755 /usr/local/bin/previs-sandbox-check

install_previsd_unit "$src"
mkdir -p /etc/systemd/system/previsd.service.d
{ manager_ending_oneshot_head; cat <<'EOT'; } >/etc/systemd/system/previsd.service.d/probe.conf
Restart=no
WatchdogSec=0
ExecStart=
ExecStart=/usr/local/bin/previs-sandbox-check
StandardOutput=truncate:/run/previs-probe.log
StandardError=inherit
EOT

# The manager's exit status is the service's (SuccessAction/FailureAction=exit-force).
status=0
container=vmtest timeout 150 unshare --pid --fork --mount-proc \
    /lib/systemd/systemd --system --unit=previsd.service --log-target=console \
    --log-level=warning </dev/null >/run/systemd-manager.log 2>&1 || status=$?
cat /run/previs-probe.log 2>/dev/null || true
if [ $status -ne 0 ]; then
    echo "--- manager log"; cat /run/systemd-manager.log
    echo "FAIL: previsd.service (probe) exited $status"
    exit 1
fi
grep -q '^running as: uid=' /run/previs-probe.log || { echo "FAIL: the probe did not run"; exit 1; }
echo "the unit's sandbox reaches every device: OK"

# A crash that repeats must not leave the box dead (previsd.service OnFailure= with
# previsd-retry.timer and .service), and a config error (exit 2) must not be retried. The real
# units, with drop-ins that only stand a failing command in for previsd and shorten the times
# (3 starts in 30 s, retry 2 s later); the starts are counted in a file.
cp "$src/systemd/previsd-retry.timer" "$src/systemd/previsd-retry.service" /etc/systemd/system/
mkdir -p /etc/systemd/system/previsd-retry.timer.d /etc/systemd/system/previsd-retry.service.d
cat >/etc/systemd/system/previsd-retry.timer.d/test.conf <<'EOT'
[Unit]
DefaultDependencies=no
[Timer]
OnActiveSec=
OnActiveSec=2
EOT
cat >/etc/systemd/system/previsd-retry.service.d/test.conf <<'EOT'
[Unit]
DefaultDependencies=no
[Service]
StandardOutput=append:/run/previs-retry.log
EOT
starts_now() { awk '/^start$/ { n++ } END { print n + 0 }' /run/previs-starts.log 2>/dev/null || echo 0; }
# A process that says READY=1 from the main PID (NotifyAccess=main), then hangs: never WATCHDOG=1.
cat >/usr/local/bin/previs-hang <<'EOT'
#!/usr/bin/python3
import os, socket, time
print("start", flush=True)
path = os.environ["NOTIFY_SOCKET"]
s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
s.connect("\0" + path[1:] if path.startswith("@") else path)
s.send(b"READY=1")
time.sleep(600)
EOT
chmod 755 /usr/local/bin/previs-hang
restart_case() {  # EXEC TYPE WATCHDOG_SEC STARTS_WANTED SECONDS: starts after SECONDS (or STARTS_WANTED)
    rm -f /run/previs-starts.log /run/previs-retry.log
    cat >/etc/systemd/system/previsd.service.d/probe.conf <<EOT
[Unit]
DefaultDependencies=no
StartLimitIntervalSec=30
StartLimitBurst=3
[Service]
Type=$2
WatchdogSec=$3
RestartSec=100ms
ExecStart=
ExecStart=$1
# How each run ended, as systemd saw it (watchdog, exit-code, …).
ExecStopPost=/bin/sh -c 'echo "result \$\$SERVICE_RESULT"'
StandardOutput=append:/run/previs-starts.log
EOT
    container=vmtest unshare --pid --fork --mount-proc /lib/systemd/systemd --system \
        --unit=previsd.service --log-target=console --log-level=info </dev/null \
        >/run/systemd-manager.log 2>&1 &
    local manager=$! waited=0
    while [ $waited -lt $(($5 * 10)) ]; do
        [ "$(starts_now)" -ge "$4" ] && break
        sleep 0.1; waited=$((waited + 1))
    done
    # The manager is unshare's child, PID 1 of its namespace: killing it ends everything in there.
    pkill -KILL -P $manager 2>/dev/null || true
    wait $manager 2>/dev/null || true
    starts_now
}
starts=$(restart_case "/bin/sh -c 'echo start; exit 1'" simple 0 5 120)
cat /run/previs-retry.log 2>/dev/null || true
[ "$starts" -ge 5 ] || { tail -40 /run/systemd-manager.log; echo "FAIL: a crash loop stopped after $starts starts"; exit 1; }
grep -q "starting it again" /run/previs-retry.log || { echo "FAIL: the retry did not say why"; exit 1; }
echo "a crash that repeats: $starts starts (3 fast, then again after the pause): OK"
starts=$(restart_case "/bin/sh -c 'echo start; exit 2'" simple 0 99 15)
cat /run/previs-retry.log 2>/dev/null || true
[ "$starts" -eq 1 ] || { tail -40 /run/systemd-manager.log; echo "FAIL: exit 2 started $starts times"; exit 1; }
grep -q "not starting it again" /run/previs-retry.log ||
    { tail -40 /run/systemd-manager.log; echo "FAIL: exit 2: the retry did not say why it waits"; exit 1; }
echo "exit 2 (a config error): started once, not retried: OK"
# The watchdog: a main process that stops feeding it is killed (SIGABRT) and started again.
starts=$(restart_case /usr/local/bin/previs-hang notify 2 2 90)
[ "$starts" -ge 2 ] || { tail -40 /run/systemd-manager.log; echo "FAIL: a hung previsd was not restarted ($starts starts)"; exit 1; }
grep -q "^result watchdog$" /run/previs-starts.log ||
    { cat /run/previs-starts.log; echo "FAIL: systemd did not end it for its watchdog"; exit 1; }
echo "a process that stops feeding the watchdog: killed and started again: OK"

# Its own namespace, /run and unit folder: nothing above is seen or touched.
[ -z "$previsd" ] || exec bash "$src/tests/systemd/socket_units_vm.sh" "$src" "$previsd"
