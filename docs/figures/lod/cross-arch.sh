#!/usr/bin/env bash
# Does meshoptimizer simplify the bunny to the same bits on x86-64 and aarch64? Builds simplify-check.cpp with
# the meshopt crate's copy of meshoptimizer natively and for aarch64 (run under qemu-aarch64), with the flags of
# .cargo/config.toml (-ffp-contract=off) and, for contrast, with GCC's contraction into fused multiply-adds;
# prints each one's result for three bounds. Needs g++, aarch64-linux-gnu-g++ and qemu-aarch64
# (deploy/aarch64/build.sh --install) and bunny.obj (get-bunny.sh).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cd "$here/../../.."
src=$(cargo metadata --format-version 1 --locked | python3 -c \
  'import json, sys; print(next(p["manifest_path"] for p in json.load(sys.stdin)["packages"] if p["name"] == "meshopt"))')
src="$(dirname "$src")/vendor/src"
[ -f "$here/bunny.obj" ] || bash "$here/get-bunny.sh"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
files=("$here/simplify-check.cpp" "$src/simplifier.cpp" "$src/allocator.cpp")
g++ -O3 -std=c++11 -ffp-contract=off -I"$src" "${files[@]}" -o "$tmp/x86"
aarch64-linux-gnu-g++ -O3 -std=c++11 -ffp-contract=off -static -I"$src" "${files[@]}" -o "$tmp/arm"
aarch64-linux-gnu-g++ -O3 -std=c++11 -ffp-contract=fast -static -I"$src" "${files[@]}" -o "$tmp/arm-fma"
for bound in 0.0234 0.1 1.0; do
  echo "bound $bound"
  echo "  x86-64:                $("$tmp/x86" "$here/bunny.obj" "$bound")"
  echo "  aarch64:               $(qemu-aarch64 "$tmp/arm" "$here/bunny.obj" "$bound")"
  echo "  aarch64, contracted:   $(qemu-aarch64 "$tmp/arm-fma" "$here/bunny.obj" "$bound")"
done
