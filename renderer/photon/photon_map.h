// The photon map (Jensen 1996; Jensen 2001, "Realistic Image Synthesis Using
// Photon Mapping", ch. 6): photons in a balanced kd-tree with k-nearest and
// range queries.
//
// Our own tree, not nanoflann (Debian's libnanoflann-dev 1.4.3 is in the
// archive but not installed here): nanoflann splits at the bounding box's
// mid-point into leaf buckets, so its trees are not balanced, and it orders
// equidistant neighbours by traversal order; Jensen's map is a balanced tree
// (median split on the axis of largest extent, ch. 6.3) whose depth is
// log2(n) whatever the photon distribution (caustics pile photons into tiny
// regions), and our estimators need neighbour sets that are a function of
// the photons alone, so that a render's bytes do not depend on anything
// but the seed (ties go to the lower index in the built array, which the
// build fixes). The tree is
// implicit: after the build, the photons of a subtree occupy a range
// [lo, hi) of one array whose median element mid = (lo + hi) / 2 is the
// node, its split axis kept in two spare bits of the photon (no pointers, no
// extra bytes per photon; Jensen's "balanced heap" layout serves the same end).
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

#include "core/math.h"
#include "core/spectrum.h"

namespace rm {

// What a photon carries (Jensen 2001, sec. 5.2: power, position, incoming
// direction); power as RGB flux, wi pointing back along the photon's
// path (away from the surface), float for all three: 40 bytes with the
// flags (Jensen packs into 20 bytes with a shared-exponent power and
// quantised angles; the float layout keeps the bias analysis free of
// quantisation error).
struct Photon {
    Vec3 p;
    Color power{0.f};
    Vec3 wi;
    uint32_t flags = 0;  // bits 0-1: kd split axis (set by the build); bits 2+: kPhoton* below
};
// The light path had a non-specular vertex before this one (L ... D ... x):
// it is indirect light at x, not direct or caustic light.
constexpr uint32_t kPhotonIndirect = 1u << 2;
// The photon is the first vertex of its light path (direct light at x).
constexpr uint32_t kPhotonDirect = 1u << 3;
// Scenes with media: the light path scattered in a medium before this
// vertex (V), or in a medium behind a non-null boundary (B; MediumTracker),
// so the photon's light belongs to the volume or subsurface class.
constexpr uint32_t kPhotonVolumePath = 1u << 4;
constexpr uint32_t kPhotonSubsurfacePath = 1u << 5;

struct Neighbour {
    float d2;      // squared distance to the query point
    uint32_t idx;  // index into PhotonMap::photons()
};

class PhotonMap {
public:
    PhotonMap() = default;
    // Builds the balanced tree over `photons` (taken over and reordered in
    // place); `threads` > 1 splits the top levels' nodes and then builds
    // their subtrees in parallel (the tree is the same whatever the thread
    // count). keep_ids keeps each photon's input index (ids()). `poll`
    // (the pass loop's poll_once), when given, is called about every 50 ms
    // from the calling thread; false cancels the build, which then leaves
    // an empty map and returns false.
    bool build(std::vector<Photon> photons, int threads = 1, bool keep_ids = false,
               const std::function<bool()>& poll = {});
    // The photon array, emptied but with its capacity, for the next pass's
    // photons (sppm); the map is empty after it.
    std::vector<Photon> release();
    size_t size() const { return photons_.size(); }
    bool empty() const { return photons_.empty(); }
    const std::vector<Photon>& photons() const { return photons_; }
    const std::vector<uint32_t>& ids() const { return ids_; }
    // The k nearest photons with d2 <= r2_max, nearest first (ties: lower
    // index in photons() first). Photons whose light path is longer than
    // max_depth segments (flags bits 8-15, photon_trace.h) are passed over.
    // `out` is cleared.
    void knn(const Vec3& q, int k, float r2_max, std::vector<Neighbour>& out, int max_depth = 255) const;
    // Every photon with d2 <= r2, in tree order. `out` is cleared.
    void range(const Vec3& q, float r2, std::vector<Neighbour>& out) const;
    static constexpr size_t bytes_per_photon() { return sizeof(Photon); }
    // What a build needs beside the photons, per photon (memory.h): its key
    // and split axis.
    static constexpr size_t build_bytes_per_photon() { return sizeof(BuildKey) + 1; }

    // A photon's position and input index, what the build sorts.
    struct BuildKey {
        Vec3 p;
        uint32_t id;
    };

private:
    bool cancelled_build();

    std::vector<Photon> photons_;
    std::vector<uint32_t> ids_;
    // The build's scratch, kept for the next build.
    std::vector<BuildKey> keys_;
    std::vector<uint8_t> axis_;
};

}  // namespace rm
