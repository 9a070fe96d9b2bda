#!/usr/bin/env bash
# The Stanford bunny for the level-of-detail table (docs/RESULTS.md, "Level of detail"), from the npm package
# `bunny` (positions and cells of the Stanford scan's 3 674-triangle reconstruction), written as an OBJ beside this
# script: docs/figures/lod/bunny.obj, which git ignores (the mesh is not ours to commit).
#
#   bash docs/figures/lod/get-bunny.sh [LEVELS]
#
# The package's bunny is coarse: 3 674 triangles, about 0.3 units apart on a bunny 10 units wide, already fewer
# than a 256-pixel view of it needs to simplify. LEVELS (default 3) rounds of Loop subdivision (Loop 1987,
# "Smooth subdivision surfaces based on triangles": new edge points 3/8·(ends) + 1/8·(opposite corners), old
# points moved by Warren's β; on the scan's open borders, edge midpoints and 3/4·v + 1/8·(border neighbours))
# make it dense and smooth: 3 674 · 4^LEVELS triangles (235 136 for 3). Needs npm and node.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
levels="${1:-3}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && npm pack --silent bunny >/dev/null && tar xzf bunny-*.tgz)
node - "$tmp/package" "$levels" "$here/bunny.obj" <<'JS'
const [pkg, levelsArg, out] = process.argv.slice(2);
const bunny = require(pkg);
let pos = bunny.positions.map((p) => p.slice());
let cells = bunny.cells.map((c) => c.slice());

// One round of Loop subdivision.
function loop(pos, cells) {
  const key = (a, b) => (a < b ? a * 1e7 + b : b * 1e7 + a);
  const edges = new Map(); // key -> { a, b, opposite: [..], index }
  for (const [i, j, k] of cells) {
    for (const [a, b, c] of [[i, j, k], [j, k, i], [k, i, j]]) {
      const e = edges.get(key(a, b)) || { a, b, opposite: [] };
      e.opposite.push(c);
      edges.set(key(a, b), e);
    }
  }
  const n = pos.length;
  const next = pos.map(() => [0, 0, 0]);
  const neighbours = pos.map(() => new Set());
  const border = pos.map(() => []);
  for (const e of edges.values()) {
    neighbours[e.a].add(e.b);
    neighbours[e.b].add(e.a);
    if (e.opposite.length !== 2) {
      border[e.a].push(e.b);
      border[e.b].push(e.a);
    }
  }
  // Old points.
  for (let v = 0; v < n; v++) {
    const p = pos[v];
    if (border[v].length === 2) {
      const [a, b] = border[v];
      for (let k = 0; k < 3; k++) next[v][k] = 0.75 * p[k] + 0.125 * (pos[a][k] + pos[b][k]);
    } else if (border[v].length > 0 || neighbours[v].size < 3) {
      next[v] = p.slice();
    } else {
      const m = neighbours[v].size;
      const beta = m === 3 ? 3 / 16 : 3 / (8 * m);
      const sum = [0, 0, 0];
      for (const u of neighbours[v]) for (let k = 0; k < 3; k++) sum[k] += pos[u][k];
      for (let k = 0; k < 3; k++) next[v][k] = (1 - m * beta) * p[k] + beta * sum[k];
    }
  }
  // Edge points.
  for (const e of edges.values()) {
    const [a, b] = [pos[e.a], pos[e.b]];
    let p;
    if (e.opposite.length === 2) {
      const [c, d] = [pos[e.opposite[0]], pos[e.opposite[1]]];
      p = [0, 1, 2].map((k) => 0.375 * (a[k] + b[k]) + 0.125 * (c[k] + d[k]));
    } else {
      p = [0, 1, 2].map((k) => 0.5 * (a[k] + b[k]));
    }
    e.index = next.length;
    next.push(p);
  }
  const mid = (a, b) => edges.get(key(a, b)).index;
  const out = [];
  for (const [i, j, k] of cells) {
    const [ij, jk, ki] = [mid(i, j), mid(j, k), mid(k, i)];
    out.push([i, ij, ki], [ij, j, jk], [ki, jk, k], [ij, jk, ki]);
  }
  return [next, out];
}

for (let l = 0; l < Number(levelsArg); l++) [pos, cells] = loop(pos, cells);
const lines = [`# The Stanford bunny (npm package bunny), ${levelsArg} rounds of Loop subdivision: ${cells.length} triangles`];
for (const p of pos) lines.push(`v ${p.map((x) => x.toFixed(6)).join(' ')}`);
for (const c of cells) lines.push(`f ${c[0] + 1} ${c[1] + 1} ${c[2] + 1}`);
require('fs').writeFileSync(out, lines.join('\n') + '\n');
console.log(`${out}: ${pos.length} vertices, ${cells.length} triangles`);
JS
