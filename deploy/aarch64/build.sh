#!/usr/bin/env bash
# Build photon-worker (and photon-coordinator) for aarch64 Linux on an x86-64 Debian 12 machine.
#
#   bash deploy/aarch64/build.sh [--install] [--worker-only]
#
# --install first installs Debian's packages for it (as root): rustc-web/cargo-web 1.96 with the aarch64 standard
# library, the aarch64 cross linker, C and C++ compilers and C library, and qemu-user to run the result here. The
# build uses Debian's cargo and rustc (rustup's rustc cannot link Debian's aarch64 std) into target/aarch64/, apart
# from the native build. Output: target/aarch64/aarch64-unknown-linux-gnu/release/photon-worker. Run it here under emulation:
#   qemu-aarch64 target/aarch64/aarch64-unknown-linux-gnu/release/photon-worker --listen 127.0.0.1:0
# (not with -L or QEMU_LD_PREFIX: the binary is dynamically linked against the cross glibc qemu finds itself).
# tests/tests/mixed_arch.rs runs this worker beside an x86-64 one (CI builds it first; about 6 minutes).
set -euo pipefail
cd "$(dirname "$0")/../.."
install=no
packages=(-p photon-worker -p photon-coordinator)
for arg in "$@"; do
  case $arg in
    --install) install=yes ;;
    --worker-only) packages=(-p photon-worker) ;; # what CI needs, minutes sooner
    *) echo "usage: build.sh [--install] [--worker-only]" >&2; exit 2 ;;
  esac
done
if [ "$install" = yes ]; then
  dpkg --add-architecture arm64
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    rustc-web cargo-web libstd-rust-web-dev:arm64 gcc-aarch64-linux-gnu g++-aarch64-linux-gnu libc6-dev-arm64-cross \
    qemu-user >/dev/null
fi
# g++: photon-core builds meshoptimizer's C++ (the meshes' level of detail) with the cc crate.
for tool in /usr/bin/cargo /usr/bin/rustc aarch64-linux-gnu-gcc aarch64-linux-gnu-g++; do
  command -v "$tool" >/dev/null || { echo "$tool is missing: run with --install (as root)" >&2; exit 1; }
done
# 128-byte cache lines suit the big ARM server cores (kiddo's layout; speed only, never results).
PATH=/usr/bin:$PATH CARGO_TARGET_DIR=target/aarch64 RUSTFLAGS="--cfg cache_line_128" \
  cargo build --release --locked --target aarch64-unknown-linux-gnu "${packages[@]}"
ls -l target/aarch64/aarch64-unknown-linux-gnu/release/photon-worker
