// The few calls the anchors binary makes into tinybvh (src/tinybvh.rs declares them). Compiled against the header
// that tinybvh-rs bundles, without TINYBVH_IMPLEMENTATION: the definitions are those tinybvh-rs compiled (build.rs).
//
// Why a shim and not tinybvh-rs's Rust API: that API (0.1.0-beta.3) offers BVH8_CPU's closest hit but no occlusion
// query, builds through the reference binned builder without tinybvh's CombineLeafs step (BVH8_CPU::Build's
// PrepareBuild4_8), and its `Ray` is 64 bytes where the bundled header's is 128 (aligned to 64: the hit record
// gained an instance index and 64 bytes of user data), so `Ray::new`, which returns the C++ Ray by value, writes
// past the Rust value. Here tinybvh's own types and entry points are used, as the header documents them.
#include "tiny_bvh.h"
#include <sched.h>
#include <cstddef>
#include <cstdint>

using tinybvh::BVH8_CPU;

extern "C" {

// BVH8_CPU::Build: tinybvh's default builder (BuildAVX, binned SAH), PrepareBuild4_8 (CombineLeafs, SplitLeafs to
// 4), Compact, the MBVH<8> conversion and the BVH8_CPU layout. `vertices` holds 3 × 4 floats per triangle, 16-byte
// aligned; BVH8_CPU copies the triangles into its leaves, so the vertices need not outlive the build.
void* anchors_tinybvh_build(const float* vertices, uint32_t triangles) {
    BVH8_CPU* bvh = new BVH8_CPU();
    bvh->Build(reinterpret_cast<const tinybvh::bvhvec4*>(vertices), triangles);
    return bvh;
}

void anchors_tinybvh_free(void* bvh) { delete static_cast<BVH8_CPU*>(bvh); }

// Bytes held after Build (every buffer the BVH8_CPU owns, as allocated: it keeps the binary BVH with its index
// array and build fragments, and the MBVH<8> it was converted from, and has no call to release them), and in
// `traversal` the bytes its queries read: the interleaved 256-byte nodes and 192-byte leaves of 4 triangles
// (vertex and two edges, SoA, padded by repeating a triangle), the layout's whole copy of the geometry.
size_t anchors_tinybvh_bytes(const void* p, size_t* traversal) {
    const BVH8_CPU* b = static_cast<const BVH8_CPU*>(p);
    const auto& mbvh = b->bvh8;
    const auto& bvh = mbvh.bvh;
    *traversal = size_t(b->usedBlocks) * 64;
    return size_t(b->allocatedBlocks) * 64 + size_t(mbvh.allocatedNodes) * sizeof(tinybvh::MBVH<8>::MBVHNode) +
           size_t(bvh.allocatedNodes) * sizeof(tinybvh::BVH::BVHNode) + size_t(bvh.idxCount) * sizeof(uint32_t) +
           size_t(bvh.triCount) * sizeof(tinybvh::BVHBase::Fragment);
}

// Casts rays[0..n] (origin and direction, 6 floats each; tinybvh normalizes the direction) with tmax = BVH_FAR
// (1e30, tinybvh's infinity), the Ray made per query as embree_rays makes its RTCRayHit. Closest hit
// (BVH8_CPU::Intersect) or, with `any`, occlusion (BVH8_CPU::IsOccluded); returns the number of rays that hit.
size_t anchors_tinybvh_cast(const void* p, const float* rays, size_t n, int any) {
    const BVH8_CPU* b = static_cast<const BVH8_CPU*>(p);
    size_t hits = 0;
    for (size_t i = 0; i < n; i++) {
        const float* x = rays + 6 * i;
        tinybvh::Ray ray(tinybvh::bvhvec3(x[0], x[1], x[2]), tinybvh::bvhvec3(x[3], x[4], x[5]));
        if (any) {
            hits += b->IsOccluded(ray);
        } else {
            b->Intersect(ray);
            hits += ray.hit.t < BVH_FAR;
        }
    }
    return hits;
}

// tinybvh's threaded builds (above 50 000 triangles) start std::thread::hardware_concurrency() workers whatever
// the caller wants. To build on THREADS threads the calling thread is held to THREADS of its CPUs while it builds:
// the workers it starts inherit that mask (they live on, idle, after the build). Returns 0 where THREADS covers
// every CPU already, 1 where it pinned; anchors_unpin restores the mask.
static cpu_set_t saved_mask;

int anchors_pin(int threads) {
    if (sched_getaffinity(0, sizeof saved_mask, &saved_mask) != 0) return -1;
    if (threads >= CPU_COUNT(&saved_mask)) return 0;
    cpu_set_t mask;
    CPU_ZERO(&mask);
    for (int cpu = 0, kept = 0; cpu < CPU_SETSIZE && kept < threads; cpu++)
        if (CPU_ISSET(cpu, &saved_mask)) CPU_SET(cpu, &mask), kept++;
    return sched_setaffinity(0, sizeof mask, &mask) == 0 ? 1 : -1;
}

void anchors_unpin(void) { sched_setaffinity(0, sizeof saved_mask, &saved_mask); }

}
