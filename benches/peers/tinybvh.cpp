// tinybvh (Jacco Bikker's single-header BVH library, https://github.com/jbikker/tinybvh) as a
// peer for the benches: a C interface over its binary BVH builders and its fastest CPU
// single-ray layout, BVH8_CPU. Compiled by build.rs with the `tinybvh` feature, against the
// `tiny_bvh.h` in $TINYBVH_DIR (benches/peers/tinybvh_fetch.sh fetches version 1.6.8).
// Single-threaded builds, as every contender in the benches.
#define NO_THREADED_BUILDS
#define TINYBVH_IMPLEMENTATION
#include "tiny_bvh.h"

#include <cstddef>
#include <cstdint>
#include <cmath>

using namespace tinybvh;

// strahl's `Ray`: origin, tmin, direction, tmax (8 floats, #[repr(C)]).
struct StrahlRay {
    float ox, oy, oz, tmin, dx, dy, dz, tmax;
};

// tinybvh normalises a ray's direction; strahl's distances are in units of the direction as
// given, so a finite tmax is scaled by its length. (tmin is not a tinybvh notion: the benches'
// rays start at 0.)
static inline Ray to_tinybvh(const StrahlRay& r) {
    const float len = std::sqrt(r.dx * r.dx + r.dy * r.dy + r.dz * r.dz);
    const float t = std::isfinite(r.tmax) ? r.tmax * len : BVH_FAR;
    return Ray(bvhvec3(r.ox, r.oy, r.oz), bvhvec3(r.dx, r.dy, r.dz), t);
}

extern "C" {

// A binary BVH (tinybvh's `BVH`), reused across builds.
void* strahl_tb_bvh_new() { return new BVH(); }
void strahl_tb_bvh_free(void* b) { delete static_cast<BVH*>(b); }

// Builds over `n` triangles given as 3n vertices of four floats (16-byte aligned; tinybvh keeps
// a pointer to them). mode 0: `Build` (binned SAH, 8 bins), 1: `BuildAVX` (the same with AVX
// binning), 2: `BuildHQ` (spatial splits). Only the build: the bench measures the tree itself.
void strahl_tb_bvh_build(void* b, const float* verts, uint32_t n, int mode) {
    BVH* bvh = static_cast<BVH*>(b);
    const bvhvec4* v = reinterpret_cast<const bvhvec4*>(verts);
    if (mode == 1) bvh->BuildAVX(v, n);
    else if (mode == 2) bvh->BuildHQ(v, n);
    else bvh->Build(v, n);
}

// The last build's nodes (32 bytes each: min, left child or first primitive, max, primitive
// count; siblings adjacent, the root at 0, slot 1 unused) and primitive indices.
const void* strahl_tb_bvh_nodes(const void* b, uint32_t* count) {
    const BVH* bvh = static_cast<const BVH*>(b);
    *count = bvh->usedNodes;
    return bvh->bvhNode;
}
const uint32_t* strahl_tb_bvh_prims(const void* b, uint32_t* count) {
    const BVH* bvh = static_cast<const BVH*>(b);
    *count = bvh->idxCount;
    return bvh->primIdx;
}

// A BVH8_CPU (8-wide nodes, leaves of 4 triangles) built by `Build` (0) or `BuildHQ` (1).
void* strahl_tb_bvh8_new(const float* verts, uint32_t n, int hq) {
    BVH8_CPU* b = new BVH8_CPU();
    const bvhvec4* v = reinterpret_cast<const bvhvec4*>(verts);
    if (hq) b->BuildHQ(v, n); else b->Build(v, n);
    return b;
}
void strahl_tb_bvh8_free(void* b) { delete static_cast<BVH8_CPU*>(b); }

// Closest hits, one `Intersect` per ray; returns how many rays hit.
size_t strahl_tb_bvh8_intersect(const void* b, const float* rays, size_t n) {
    const BVH8_CPU* bvh = static_cast<const BVH8_CPU*>(b);
    const StrahlRay* r = reinterpret_cast<const StrahlRay*>(rays);
    size_t hits = 0;
    for (size_t i = 0; i < n; i++) {
        Ray ray = to_tinybvh(r[i]);
        const float t0 = ray.hit.t;
        bvh->Intersect(ray);
        hits += ray.hit.t < t0;
    }
    return hits;
}

// Any hits, one `IsOccluded` per ray; returns how many rays are occluded.
size_t strahl_tb_bvh8_occluded(const void* b, const float* rays, size_t n) {
    const BVH8_CPU* bvh = static_cast<const BVH8_CPU*>(b);
    const StrahlRay* r = reinterpret_cast<const StrahlRay*>(rays);
    size_t hits = 0;
    for (size_t i = 0; i < n; i++) hits += bvh->IsOccluded(to_tinybvh(r[i]));
    return hits;
}

}
