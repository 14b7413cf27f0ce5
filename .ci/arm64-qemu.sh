#!/usr/bin/env bash
# The arm64 binaries on the emulated board: ecmxfd, ecmxfctl and the hw-emu
# preload library (sim/hw-emu) cross-built for aarch64-unknown-linux-gnu
# and run under qemu-user against the host's `ecmxf-sim serve`:
#   1. `ecmxfd probe` with config/ecmxfd-rpi.toml passes every step;
#   2. the daemon reaches OP, input frames rise between two reads
#      (`ecmxfctl --json master`, the arm64 ecmxfctl), an SDO upload
#      answers, and SIGTERM stops it within two seconds with status 0;
#   3. the arm64 .deb (packaging/build-deb.sh --target ...) is built, its
#      contents listed, and its own ecmxfd and ecmxfctl run under qemu.
# Exits non-zero at the first step that fails. Runs on its own from a clean
# clone (docs/packaging.md, "The arm64 binaries on an emulated board");
# CI runs it last, after the .deb stage. Installs what it needs with apt when missing (as
# root, or with passwordless sudo). qemu-aarch64 is called explicitly: no
# binfmt_misc registration is needed.
set -euo pipefail
cd "$(dirname "$0")/.."

export CARGO_TERM_COLOR=never
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"
target=aarch64-unknown-linux-gnu
sysroot=/usr/aarch64-linux-gnu

# Each stage's time is printed when it ends: what the check costs in CI.
start=$(date +%s)
stage_start=$start
stage_name=""
stage() {
    local now
    now=$(date +%s)
    [ -z "$stage_name" ] || echo "   ($stage_name: $((now - stage_start)) s)"
    echo "== arm64: $*"
    stage_name=$1
    stage_start=$now
}

# --- tools -----------------------------------------------------------------
stage "tools"
missing=()
command -v qemu-aarch64 >/dev/null || missing+=(qemu-user)
command -v aarch64-linux-gnu-gcc >/dev/null || missing+=(gcc-aarch64-linux-gnu)
[ -e "$sysroot/include/stdio.h" ] || missing+=(libc6-dev-arm64-cross)
# The guest's dynamic loader and libc (qemu -L), and libgcc_s for Rust's
# unwinder.
[ -e "$sysroot/lib/ld-linux-aarch64.so.1" ] || missing+=(libc6-arm64-cross)
[ -e "$sysroot/lib/libgcc_s.so.1" ] || missing+=(libgcc-s1-arm64-cross)
command -v dpkg-deb >/dev/null || missing+=(dpkg)
command -v python3 >/dev/null || missing+=(python3)
if [ "${#missing[@]}" -gt 0 ]; then
    echo "installing: ${missing[*]}"
    sudo=""
    [ "$(id -u)" = 0 ] || sudo="sudo -n"
    $sudo apt-get update -q >/dev/null
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends "${missing[@]}" >/dev/null
fi
if command -v rustup >/dev/null; then
    rustup target add "$target" >/dev/null 2>&1 || echo "rustup target add $target failed: building with what is installed"
fi
qemu-aarch64 --version | head -n 1
export CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc

# --- builds ----------------------------------------------------------------
# The simulator runs on the host: the release build when one is there (CI's
# .deb stage made it), else the debug build; cargo rebuilds it if stale.
if [ -x target/release/ecmxf-sim ]; then
    stage "host ecmxf-sim (release)"
    cargo build --release -p ecmxf-sim --bins
    sim=target/release/ecmxf-sim
else
    stage "host ecmxf-sim (debug)"
    cargo build -p ecmxf-sim --bins
    sim=target/debug/ecmxf-sim
fi

# Release: the .deb (step 3) needs the release cross build anyway, and the
# run reuses it; a debug cross build would be a second full build.
stage "cross build (release) of ecmxfd, ecmxfctl, ecmxf-hw-emu for $target"
cargo build --release --target "$target" -p ecmxfd -p ecmxfctl -p ecmxf-hw-emu
out=target/$target/release
for f in ecmxfd ecmxfctl libecmxf_hw_emu.so; do
    # ELF e_machine (bytes 18-19, little-endian): 183 is EM_AARCH64.
    machine=$(od -An -tu2 -j18 -N2 "$out/$f" | tr -d ' ')
    [ "$machine" = 183 ] || { echo "$out/$f is not an aarch64 ELF (e_machine $machine)" >&2; exit 1; }
done
preload=$PWD/$out/libecmxf_hw_emu.so
qemu=(qemu-aarch64 -L "$sysroot")

# --- the run ---------------------------------------------------------------
work=$(mktemp -d)
pids=()
# Stops what this script started, the last started first (the daemon before
# the simulator it talks to); SIGKILL after 3 s.
cleanup() {
    local status=$? i pid
    for ((i = ${#pids[@]} - 1; i >= 0; i--)); do
        pid=${pids[i]}
        if kill "$pid" 2>/dev/null; then
            for _ in $(seq 30); do
                kill -0 "$pid" 2>/dev/null || break
                sleep 0.1
            done
            kill -KILL "$pid" 2>/dev/null || true
        fi
        wait "$pid" 2>/dev/null || true
    done
    if [ "$status" != 0 ]; then
        for log in "$work/ecmxfd.log" "$work/sim.log"; do
            [ -s "$log" ] || continue
            echo "--- ${log##*/} (last 40 lines)" >&2
            tail -n 40 "$log" >&2
        done
    fi
    rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
fail() {
    echo "arm64: FAIL: $*" >&2
    exit 1
}

hw_sock=$work/hw.sock
api_sock=$work/ecmxfd.sock
# The emulated board's environment, for the guest (-E: qemu itself must not
# get the aarch64 library in its own LD_PRELOAD).
emu=(-E "LD_PRELOAD=$preload" -E "ECMXF_SIM_SOCKET=$hw_sock")
ctl() { "${qemu[@]}" "$out/ecmxfctl" --socket "$api_sock" "$@"; }
# A field of a JSON object on stdin: json_field counters input_frames.
json_field() {
    python3 -c 'import json, sys
v = json.load(sys.stdin)
for k in sys.argv[1:]:
    v = v[k]
print(json.dumps(v) if isinstance(v, (dict, list, bool)) or v is None else v)' "$@"
}

stage "simulator: $sim serve (demo network, strict data lengths)"
"$sim" serve --socket "$hw_sock" --network config/demo-network.toml --strict-lengths >"$work/sim.log" 2>&1 &
sim_pid=$!
pids+=("$sim_pid")
for _ in $(seq 100); do
    [ -S "$hw_sock" ] && break
    kill -0 "$sim_pid" 2>/dev/null || fail "ecmxf-sim serve exited"
    sleep 0.1
done
[ -S "$hw_sock" ] || fail "ecmxf-sim serve made no socket in 10 s"
cat "$work/sim.log"

# --force: a daemon on the configuration's API socket (an installed service)
# drives another chip, not this simulator; the probe would refuse for it.
stage "ecmxfd probe (arm64, qemu-user, emulated spidev and gpiochip)"
probe_status=0
"${qemu[@]}" "${emu[@]}" "$out/ecmxfd" probe --force --config config/ecmxfd-rpi.toml >"$work/probe.log" 2>&1 ||
    probe_status=$?
cat "$work/probe.log"
[ "$probe_status" = 0 ] || fail "ecmxfd probe exited with $probe_status"
steps=$(grep -cE '^[0-9]+\. ' "$work/probe.log" || true)
ok_steps=$(grep -cE '^[0-9]+\. .* ok    ' "$work/probe.log" || true)
grep -qE '^all [0-9]+ steps passed' "$work/probe.log" || fail "probe did not report all steps passed"
[ "$steps" -gt 0 ] && [ "$steps" = "$ok_steps" ] || fail "probe: $ok_steps of $steps steps ok"

stage "ecmxfd (arm64, qemu-user) with config/ecmxfd-rpi.toml"
"${qemu[@]}" "${emu[@]}" "$out/ecmxfd" --config config/ecmxfd-rpi.toml --socket "$api_sock" \
    --status-every 0 >"$work/ecmxfd.log" 2>&1 &
daemon_pid=$!
pids+=("$daemon_pid")
state=""
for _ in $(seq 120); do
    kill -0 "$daemon_pid" 2>/dev/null || fail "ecmxfd exited before OP"
    if [ -S "$api_sock" ] && master=$(ctl --json master 2>/dev/null); then
        state=$(json_field state <<<"$master")/$(json_field phase <<<"$master")
        [ "$state" = OP/RUNNING ] && break
    fi
    sleep 0.5
done
[ "$state" = OP/RUNNING ] || fail "ecmxfd not in OP after 60 s (state/phase: ${state:-no answer})"
echo "OP after $(($(date +%s) - stage_start)) s"

m1=$(ctl --json master)
sleep 1
m2=$(ctl --json master)
in1=$(json_field counters input_frames <<<"$m1")
in2=$(json_field counters input_frames <<<"$m2")
flowing=$(json_field process_data_flowing <<<"$m2")
echo "input frames: $in1, 1 s later $in2; process data flowing: $flowing; health: $(json_field health <<<"$m2")"
[ "$in2" -gt "$in1" ] || fail "input frames did not rise ($in1 -> $in2)"
[ "$flowing" = true ] || fail "process data not flowing"
ctl master

stage "SDO upload"
upload=$(ctl --json upload -p 1 0x6041) || fail "ecmxfctl upload -p 1 0x6041 failed"
echo "$upload"
[ "$(json_field index <<<"$upload")" = $((0x6041)) ] && json_field value <<<"$upload" >/dev/null ||
    fail "upload -p 1 0x6041 answered without the object's value"

stage "SIGTERM"
kill -TERM "$daemon_pid"
stopped=""
for _ in $(seq 20); do
    if ! kill -0 "$daemon_pid" 2>/dev/null; then
        stopped=yes
        break
    fi
    sleep 0.1
done
[ -n "$stopped" ] || fail "ecmxfd still running 2 s after SIGTERM"
daemon_status=0
wait "$daemon_pid" || daemon_status=$?
[ "$daemon_status" = 0 ] || fail "ecmxfd exited with $daemon_status after SIGTERM"
grep -E 'SIGTERM|stopped' "$work/ecmxfd.log" | sed 's/^/ecmxfd: /'
grep -q 'stopped' "$work/ecmxfd.log" || fail "ecmxfd logged no stop"

# --- the .deb --------------------------------------------------------------
stage "arm64 .deb (packaging/build-deb.sh --target $target)"
version=$(cargo metadata --no-deps --format-version 1 |
    python3 -c 'import json, sys; print(next(p["version"] for p in json.load(sys.stdin)["packages"] if p["name"] == "ecmxfd"))')
deb=target/$target/debian/ecmxfd_${version}-1_arm64.deb
rm -f "$deb"
packaging/build-deb.sh --target "$target"
[ -f "$deb" ] || fail "packaging/build-deb.sh made no $deb"
echo "$deb ($(du -k "$deb" | cut -f1) kB):"
dpkg-deb -c "$deb"
[ "$(dpkg-deb -f "$deb" Architecture)" = arm64 ] || fail "$deb: Architecture is not arm64"
dpkg-deb -f "$deb" Package Version Architecture Depends
mkdir "$work/deb"
dpkg-deb -x "$deb" "$work/deb"
for f in ecmxfd ecmxfctl ecmxf-sim; do
    [ -x "$work/deb/usr/bin/$f" ] || fail "$deb has no /usr/bin/$f"
    "${qemu[@]}" "$work/deb/usr/bin/$f" --version || fail "the packaged $f does not run under qemu-aarch64"
done

stage "arm64 under qemu-user: all passed in $(($(date +%s) - start)) s"
