# Sourced by the systemd checks in the test VM (devices_vm.sh, sandbox_vm.sh, socket_units_vm.sh):
# the box as `cmake --install --prefix /usr` and systemd-sysusers leave it, and the unit head that
# runs a check under systemd.

# Group previs (systemd-sysusers makes it) and our udev rule, applied to the GPIO nodes there now.
install_previs_udev_rule() {  # SOURCE_DIR
    getent group previs >/dev/null || groupadd --system previs
    cp "$1/systemd/60-previs-gpio.rules" /etc/udev/rules.d/
    udevadm control --reload
    udevadm trigger --action=add --subsystem-match=gpio
    udevadm settle --timeout=30
}

# previsd.service from its template, with an install's paths under /usr.
install_previsd_unit() {  # SOURCE_DIR
    sed -e 's|@PREVIS_BINDIR@|/usr/bin|; s|@PREVIS_CONFDIR@|/etc/previs|' \
        -e 's|@PREVIS_DOCDIR@|/usr/share/doc/previs|' \
        "$1/systemd/previsd.service.in" >/etc/systemd/system/previsd.service
}

# The head of a oneshot whose end ends the manager (systemd as PID 1 of the check's namespace)
# with the oneshot's exit status; the caller writes the rest of its [Service] section after it.
manager_ending_oneshot_head() {
    printf '%s\n' '[Unit]' 'DefaultDependencies=no' 'SuccessAction=exit-force' \
        'FailureAction=exit-force' '[Service]' 'Type=oneshot'
}
