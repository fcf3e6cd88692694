#include "photon/photon_map.h"

#include <algorithm>
#include <stdexcept>
#include <thread>

#include "render/parallel.h"

namespace rm {

namespace {

// Our own selection instead of std::nth_element alone: libstdc++'s
// partition branches on every comparison, and on photon positions about
// half of those branches are mispredicted. select_nth partitions with
// Lomuto's scheme in its branchless form (each element swapped with the
// first not-less one, which advances by the comparison's result;
// Alexandrescu, "Lomuto's Comeback", 2020), pivot the median of three,
// and hands ranges of 32 or fewer, and any range still large after
// 2 log2(n) + 8 partitions (bad pivots), to std::nth_element, so it is
// O(n) in expectation and never worse than nth_element's bound.
// The comparison must be a strict total order (no two elements equal):
// then the element at nth, and the sets before and after it, are those
// of a full sort, whichever algorithm selects them.
template <class T, class Less>
void select_nth(T* first, T* nth, T* last, Less less) {
    int budget = 8;
    for (size_t n = size_t(last - first); n > 1; n >>= 1) budget += 2;
    while (last - first > 32 && budget-- > 0) {
        // Median of three (first, middle, last - 1) moved to last - 1.
        T* m = first + (last - first) / 2;
        T* b = last - 1;
        if (less(*m, *first)) std::swap(*m, *first);
        if (less(*b, *m)) {
            std::swap(*b, *m);
            if (less(*m, *first)) std::swap(*m, *first);
        }
        std::swap(*m, *b);  // the median is the pivot, at last - 1
        const T pivot = *b;
        T* store = first;
        for (T* it = first; it < b; ++it) {
            const T x = *it;
            const bool lt = less(x, pivot);
            *it = *store;
            *store = x;
            store += lt;
        }
        std::swap(*store, *b);  // the pivot in its sorted place
        if (nth == store) return;
        if (nth < store)
            last = store;
        else
            first = store + 1;
    }
    std::nth_element(first, nth, last, less);
}

// Jensen 2001, sec. 6.3 (balancing): the node of [lo, hi) is its median
// mid = (lo + hi) / 2 along the axis of largest extent of its photons'
// bounding box; a selection keeps it O(n) per level. Comparisons
// tie-break on the input index, so the order is a strict total order and
// every slot of the tree is the median of one range's set: the layout is
// a function of the photons alone (whichever thread splits which node,
// whatever the selection algorithm). Works on BuildKey, the photon's
// position and input index side by side (16 bytes, no indirection into
// the 40-byte photons).
size_t split_node(std::vector<PhotonMap::BuildKey>& keys, std::vector<uint8_t>& axis, size_t lo, size_t hi) {
    Vec3 bmin(kInf), bmax(-kInf);
    for (size_t i = lo; i < hi; ++i) {
        bmin = vmin(bmin, keys[i].p);
        bmax = vmax(bmax, keys[i].p);
    }
    const Vec3 ext = bmax - bmin;
    const int a = (ext.x >= ext.y && ext.x >= ext.z) ? 0 : (ext.y >= ext.z ? 1 : 2);
    const size_t mid = (lo + hi) / 2;
    // The axis as a member pointer chosen once (Vec3's operator[] would
    // branch on it in every comparison); the comparison without branches.
    const float Vec3::*c = a == 0 ? &Vec3::x : (a == 1 ? &Vec3::y : &Vec3::z);
    PhotonMap::BuildKey* k = keys.data();
    select_nth(k + lo, k + mid, k + hi, [c](const PhotonMap::BuildKey& u, const PhotonMap::BuildKey& v) {
        const float pu = u.p.*c, pv = v.p.*c;
        return bool(int(pu < pv) | (int(pu == pv) & int(u.id < v.id)));
    });
    axis[mid] = uint8_t(a);
    return mid;
}

// The whole subtree of [lo, hi), depth first (the near half recursed, the
// far half looped); `cancel` is read between nodes of 2^16 photons or more.
bool build_subtree(std::vector<PhotonMap::BuildKey>& keys, std::vector<uint8_t>& axis, size_t lo, size_t hi,
                   const std::atomic<bool>& cancel) {
    while (hi - lo > 1) {
        if (hi - lo >= (size_t(1) << 16) && cancel.load(std::memory_order_relaxed)) return false;
        const size_t mid = split_node(keys, axis, lo, hi);
        if (!build_subtree(keys, axis, lo, mid, cancel)) return false;
        lo = mid + 1;
    }
    return true;
}

inline float dist2(const Vec3& a, const Vec3& b) {
    float dx = a.x - b.x, dy = a.y - b.y, dz = a.z - b.z;
    return dx * dx + dy * dy + dz * dz;
}

// (d2, idx) order: nearer first, then lower index.
inline bool closer(const Neighbour& a, const Neighbour& b) { return a.d2 < b.d2 || (a.d2 == b.d2 && a.idx < b.idx); }

// The farthest of a full max-heap (on `closer`) of n replaced by the nearer
// `x`, in one sift down (pop_heap then push_heap sift twice). The heap
// holds the same set either way, and knn returns it sorted by a strict
// total order, so the result does not depend on how the heap is kept.
inline void replace_farthest(Neighbour* h, size_t n, const Neighbour& x) {
    size_t i = 0;
    for (;;) {
        size_t c = 2 * i + 1;
        if (c >= n) break;
        if (c + 1 < n && closer(h[c], h[c + 1])) ++c;  // the farther child
        if (!closer(x, h[c])) break;
        h[i] = h[c];
        i = c;
    }
    h[i] = x;
}

}  // namespace

bool PhotonMap::build(std::vector<Photon> photons, int threads, bool keep_ids, const std::function<bool()>& poll) {
    if (photons.size() >= (1ull << 32) - 1) throw std::invalid_argument("photon map: at most 2^32 - 2 photons");
    const size_t n = photons.size();
    threads = std::max(1, threads);
    // keys_ and axis_ keep their capacity from one build to the next (sppm
    // builds a map per pass).
    keys_.resize(n);
    axis_.assign(n, 0);
    for (size_t i = 0; i < n; ++i) keys_[i] = {photons[i].p, uint32_t(i)};
    std::atomic<bool> cancel{false};
    const std::function<bool()> no_poll = [] { return true; };
    const std::function<bool()>& poll_once = poll ? poll : no_poll;
    // 1. The top levels, breadth first: each level's nodes split in
    //    parallel, until there are enough subtrees to keep every thread
    //    busy (the first split, over all photons, runs alone).
    std::vector<std::pair<size_t, size_t>> ranges{{0, n}}, next;
    const size_t want = threads > 1 ? size_t(8 * threads) : 1;
    PollGate gate(poll_once);
    while (ranges.size() < want) {
        if (!gate()) return cancelled_build();
        bool any = false;
        for (const auto& r : ranges) any |= r.second - r.first > 4096;
        if (!any) break;
        std::vector<size_t> mids(ranges.size());
        if (!run_parallel(
                threads, ranges.size(),
                [&](size_t i, int) {
                    mids[i] = ranges[i].second - ranges[i].first > 1
                                  ? split_node(keys_, axis_, ranges[i].first, ranges[i].second)
                                  : ranges[i].first;
                },
                poll_once, cancel))
            return cancelled_build();
        next.clear();
        for (size_t i = 0; i < ranges.size(); ++i) {
            if (ranges[i].second - ranges[i].first <= 1) continue;
            next.push_back({ranges[i].first, mids[i]});
            next.push_back({mids[i] + 1, ranges[i].second});
        }
        ranges.swap(next);
    }
    // 2. The subtrees below, one task each (largest first: the ranges of a
    //    level differ by at most one photon, so in order).
    if (!gate() || !run_parallel(
                       threads, ranges.size(),
                       [&](size_t i, int) {
                           if (!build_subtree(keys_, axis_, ranges[i].first, ranges[i].second, cancel)) cancel = true;
                       },
                       poll_once, cancel))
        return cancelled_build();
    // 3. The photons into tree order in place, following the permutation's
    //    cycles (tree slot j takes input photon keys_[j].id): no second
    //    photon array. A placed slot's key id becomes kPlaced.
    constexpr uint32_t kPlaced = 0xffffffffu;
    if (keep_ids) {
        ids_.resize(n);
        for (size_t j = 0; j < n; ++j) ids_[j] = keys_[j].id;
    } else {
        ids_.clear();
    }
    for (size_t start = 0; start < n; ++start) {
        if (keys_[start].id == kPlaced) continue;
        const Photon first = photons[start];
        size_t j = start;
        for (;;) {
            const size_t src = keys_[j].id;
            keys_[j].id = kPlaced;
            if (src == start) {
                photons[j] = first;
                break;
            }
            photons[j] = photons[src];
            j = src;
        }
    }
    for (size_t i = 0; i < n; ++i) photons[i].flags = (photons[i].flags & ~3u) | axis_[i];
    photons_ = std::move(photons);
    return true;
}

bool PhotonMap::cancelled_build() {
    photons_.clear();
    ids_.clear();
    return false;
}

std::vector<Photon> PhotonMap::release() {
    std::vector<Photon> out = std::move(photons_);
    photons_.clear();
    ids_.clear();
    out.clear();
    return out;
}

void PhotonMap::knn(const Vec3& q, int k, float r2_max, std::vector<Neighbour>& out, int max_depth) const {
    out.clear();
    if (k <= 0 || photons_.empty()) return;
    float r2 = r2_max;
    // Max-heap on (d2, idx) of the best k so far; r2 shrinks to its top once full.
    auto visit = [&](size_t i) {
        float d2 = dist2(q, photons_[i].p);
        if (d2 > r2) return;
        if (max_depth < 255 && int((photons_[i].flags >> 8) & 0xffu) > max_depth) return;
        Neighbour nb{d2, uint32_t(i)};
        if (int(out.size()) < k) {
            out.push_back(nb);
            std::push_heap(out.begin(), out.end(), closer);
            if (int(out.size()) == k) r2 = out.front().d2;
        } else if (closer(nb, out.front())) {
            replace_farthest(out.data(), out.size(), nb);
            r2 = out.front().d2;
        }
    };
    // Explicit stack of subtrees with the squared distance from q to the
    // splitting plane that separates them from q: a far side is skipped
    // when popped if the radius has shrunk below it meanwhile (at most two
    // entries per level: 96 covers 2^32 photons).
    struct Range {
        uint32_t lo, hi;
        float plane_d2;
    };
    Range stack[96];
    int sp = 0;
    stack[sp++] = {0, uint32_t(photons_.size()), 0.f};
    while (sp > 0) {
        Range r = stack[--sp];
        if (r.lo >= r.hi || r.plane_d2 > r2) continue;
        uint32_t mid = (r.lo + r.hi) / 2;
        const Photon& ph = photons_[mid];
        int a = int(ph.flags & 3u);
        float d = q[a] - ph.p[a];
        visit(mid);
        // Left holds p[a] <= the split, right p[a] >= it; the near side is
        // pushed last, so it is searched first.
        if (d < 0) {
            stack[sp++] = {mid + 1, r.hi, d * d};
            stack[sp++] = {r.lo, mid, 0.f};
        } else {
            stack[sp++] = {r.lo, mid, d * d};
            stack[sp++] = {mid + 1, r.hi, 0.f};
        }
    }
    std::sort_heap(out.begin(), out.end(), closer);
}

void PhotonMap::range(const Vec3& q, float r2, std::vector<Neighbour>& out) const {
    out.clear();
    struct Range {
        uint32_t lo, hi;
    };
    Range stack[96];
    int sp = 0;
    stack[sp++] = {0, uint32_t(photons_.size())};
    while (sp > 0) {
        Range r = stack[--sp];
        if (r.lo >= r.hi) continue;
        uint32_t mid = (r.lo + r.hi) / 2;
        const Photon& ph = photons_[mid];
        int a = int(ph.flags & 3u);
        float d = q[a] - ph.p[a];
        float d2 = dist2(q, ph.p);
        if (d2 <= r2) out.push_back({d2, mid});
        if (d <= 0 || d * d <= r2) stack[sp++] = {r.lo, mid};
        if (d >= 0 || d * d <= r2) stack[sp++] = {mid + 1, r.hi};
    }
}

}  // namespace rm
