#!/usr/bin/env bash
# The crate rule of docs/ARCHITECTURE.md, checked: for each row of its "forbidden dependencies" table, the crate
# must not reach any of the listed packages through normal or build dependencies (cargo tree, so indirect paths
# count too). Exits non-zero, naming the crate, the package and the path, when one does.
set -euo pipefail
cd "$(dirname "$0")/.."
page=docs/ARCHITECTURE.md
rows=$(awk '/<!-- forbidden-dependencies -->/ { on = 1; next } on && /^\| *photon-/ { print } on && /^$/ && n++ > 0 { exit }' "$page")
if [ -z "$rows" ]; then
  echo "check-deps: no forbidden-dependencies table in $page" >&2
  exit 1
fi
fail=0
while IFS='|' read -r _ crate forbidden _; do
  crate=$(echo "$crate" | tr -d ' `')
  tree=$(cargo tree --locked -q -p "$crate" -e normal,build --prefix none | awk '{ print $1 }' | sort -u)
  deps=$(echo "$forbidden" | tr -d '`' | tr ',' ' ')
  bad=0
  for dep in $deps; do
    if echo "$tree" | grep -qx "$dep"; then
      echo "check-deps: $crate depends on $dep, which $page forbids:" >&2
      cargo tree --locked -q -p "$crate" -e normal,build -i "$dep" >&2 || true
      bad=1
    fi
  done
  [ $bad -eq 0 ] && echo "check-deps: $crate reaches none of" $deps
  fail=$((fail | bad))
done <<<"$rows"
exit $fail
