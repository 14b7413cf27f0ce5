#!/bin/sh
# Builds the ecmxfd .deb: release binaries, shell completions and man pages
# generated from ecmxfctl's clap definitions, then cargo-deb (installed into
# ~/.cargo/bin when missing). Extra arguments go to cargo-deb, e.g.
#   packaging/build-deb.sh --target aarch64-unknown-linux-gnu
# (see docs/packaging.md for the cross toolchain).
set -eu
cd "$(dirname "$0")/.."

if ! cargo deb --version >/dev/null 2>&1; then
    cargo install cargo-deb --locked --version 3.8.0
fi

target=""
prev=""
for a in "$@"; do
    if [ "$prev" = "--target" ]; then target="$a"; fi
    case "$a" in --target=*) target="${a#--target=}" ;; esac
    prev="$a"
done

if [ -n "$target" ]; then
    cargo build --release --target "$target" -p ecmxfd -p ecmxfctl -p ecmxf-sim --bins
    # Completions and man pages are the same on every architecture: make
    # them with binaries that run here.
    cargo build --release -p ecmxfctl -p ecmxfd -p ecmxf-sim --bins
else
    cargo build --release -p ecmxfd -p ecmxfctl -p ecmxf-sim --bins
fi

assets=packaging/generated
rm -rf "$assets"
mkdir -p "$assets/completions" "$assets/man"
ctl=target/release/ecmxfctl
"$ctl" completions bash >"$assets/completions/ecmxfctl.bash"
"$ctl" completions zsh >"$assets/completions/_ecmxfctl"
"$ctl" completions fish >"$assets/completions/ecmxfctl.fish"
"$ctl" man "$assets/man" >/dev/null
target/release/ecmxfd man "$assets/man" >/dev/null
target/release/ecmxf-sim man "$assets/man" >/dev/null
gzip -9n "$assets"/man/*.1 "$assets"/man/*.5 "$assets"/man/*.8

cargo deb -p ecmxfd --no-build "$@"
