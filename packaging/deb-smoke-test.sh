#!/bin/sh
# Installs the newest target/debian/ecmxfd_*.deb as a new user of a Debian
# machine would (apt resolves its dependencies), checks that everything
# landed, starts the installed daemon on the installed (simulator)
# configuration as the service would run it, asks it for a diagnosis with the
# installed ecmxfctl, and removes the package again. Needs root; CI runs it
# on a throw-away machine. Under a running systemd the service itself is
# started; in a container (no systemd) the same command line runs as the
# ecmxfd user. Then the installed binary probes the Raspberry Pi example
# configuration on emulated SPI and GPIO devices.
set -eu
cd "$(dirname "$0")/.."

deb=$(ls -t target/debian/ecmxfd_*.deb | head -n 1)
echo "installing $deb"
export DEBIAN_FRONTEND=noninteractive
apt-get install -y -q "./$deb" >/dev/null

fail() { echo "deb smoke test: $*" >&2; exit 1; }
for f in /usr/bin/ecmxfd /usr/bin/ecmxfctl /usr/bin/ecmxf-sim /usr/lib/systemd/system/ecmxfd.service \
         /lib/udev/rules.d/60-ecmxfd.rules /etc/ecmxfd/ecmxfd.toml /etc/ecmxfd/demo-network.toml \
         /usr/share/doc/ecmxfd/examples/ecmxfd-rpi.toml /usr/share/man/man1/ecmxfctl.1.gz /usr/share/man/man8/ecmxfd.8.gz \
         /usr/share/man/man5/ecmxfd.toml.5.gz /usr/share/man/man1/ecmxf-sim.1.gz \
         /usr/share/ecmxfd/proto/google/rpc/error_details.proto \
         /usr/share/bash-completion/completions/ecmxfctl; do
    [ -e "$f" ] || fail "$f not installed"
done
getent passwd ecmxfd >/dev/null || fail "no ecmxfd user"
getent group ecmxfd >/dev/null || fail "no ecmxfd group"
[ "$(stat -c %G /etc/ecmxfd/ecmxfd.toml)" = ecmxfd ] || fail "/etc/ecmxfd/ecmxfd.toml not readable by group ecmxfd"
runuser -u ecmxfd -- /usr/bin/ecmxfd --check-config /etc/ecmxfd/ecmxfd.toml

socket=/run/ecmxfd/ecmxfd.sock
pid=""
if [ -d /run/systemd/system ]; then
    systemctl restart ecmxfd
    systemctl is-active --quiet ecmxfd || fail "ecmxfd.service is not active"
else
    mkdir -p /run/ecmxfd
    chown ecmxfd:ecmxfd /run/ecmxfd
    # setpriv execs (no wrapper process), so $! is the daemon and gets SIGTERM.
    ECMXF_SOCKET=$socket setpriv --reuid=ecmxfd --regid=ecmxfd --init-groups \
        /usr/bin/ecmxfd --config /etc/ecmxfd/ecmxfd.toml --status-every 0 2>/tmp/ecmxfd-smoke.log &
    pid=$!
fi
ok=""
for _ in $(seq 1 60); do
    if ecmxfctl diag >/dev/null 2>&1; then ok=1; break; fi
    sleep 0.5
done
[ -n "$ok" ] || { cat /tmp/ecmxfd-smoke.log 2>/dev/null || true; ecmxfctl diag || true; fail "the installed daemon did not reach a healthy OP"; }
ecmxfctl slaves
if [ -n "$pid" ]; then
    kill -TERM "$pid"
    wait "$pid" || fail "ecmxfd did not stop cleanly"
else
    systemctl stop ecmxfd
fi
# The installed binary on the hardware link: the Raspberry Pi example as it
# ships, on /dev/spidev0.0 and /dev/gpiochip0 emulated in front of the
# simulator (sim/hw-emu; built by the test run before this), through every
# probe step.
sim=target/debug/ecmxf-sim
if [ -x "$sim" ]; then
    "$sim" hardware -- /usr/bin/ecmxfd probe --config /usr/share/doc/ecmxfd/examples/ecmxfd-rpi.toml \
        || fail "the installed ecmxfd did not pass the probe on emulated hardware"
else
    echo "deb smoke test: $sim not built: the probe on emulated hardware is skipped"
fi
apt-get purge -y -q ecmxfd >/dev/null
[ ! -e /usr/bin/ecmxfd ] || fail "purge left /usr/bin/ecmxfd"
echo "deb smoke test: ok ($deb)"
