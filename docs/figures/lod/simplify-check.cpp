// The simplification photon-core makes (meshopt_simplify with an absolute error, locked borders and a floor of 32
// triangles), as a small program: reads an OBJ's `v` and `f a b c` lines, prints the output's index count, a hash
// of its indices and the bits of its error. docs/figures/lod/cross-arch.sh builds it for x86-64 and aarch64 and
// compares.
#include "meshoptimizer.h"
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>
int main(int argc, char** argv) {
  FILE* f = fopen(argv[1], "r"); float bound = atof(argv[2]);
  std::vector<float> pos; std::vector<unsigned> idx; char line[512];
  while (fgets(line, sizeof line, f)) {
    float x, y, z; unsigned a, b, c;
    if (sscanf(line, "v %f %f %f", &x, &y, &z) == 3) { pos.push_back(x); pos.push_back(y); pos.push_back(z); }
    else if (sscanf(line, "f %u %u %u", &a, &b, &c) == 3) { idx.push_back(a - 1); idx.push_back(b - 1); idx.push_back(c - 1); }
  }
  std::vector<unsigned> out(idx.size()); float err = 0;
  // As photon-core: no fewer than 32 triangles (MIN_TRIANGLES).
  size_t target = 3 * (idx.size() / 3 < 32 ? idx.size() / 3 : 32);
  size_t n = meshopt_simplify(out.data(), idx.data(), idx.size(), pos.data(), pos.size() / 3, 12, target, bound,
                              meshopt_SimplifyLockBorder | meshopt_SimplifyErrorAbsolute, &err);
  unsigned long long h = 1469598103934665603ull;
  for (size_t i = 0; i < n; i++) { h ^= out[i]; h *= 1099511628211ull; }
  unsigned eb; memcpy(&eb, &err, 4);
  printf("%zu indices, hash %016llx, error bits %08x\n", n, h, eb);
}
