#include "photon/photon_map.h"

#include <algorithm>
#include <stdexcept>
#include <thread>

namespace rm {

namespace {

struct Builder {
    const std::vector<Photon>& in;
    std::vector<uint32_t>& idx;
    std::vector<uint8_t>& axis;

    // Jensen 2001, sec. 6.3 (balancing): split [lo, hi) at its median along
    // the axis of largest extent; nth_element keeps it O(n) per level.
    // Comparisons tie-break on the input index: the tree is a function of
    // the photons alone.
    void run(size_t lo, size_t hi, int par_depth) {
        while (hi - lo > 1) {
            Vec3 bmin(kInf), bmax(-kInf);
            for (size_t i = lo; i < hi; ++i) {
                bmin = vmin(bmin, in[idx[i]].p);
                bmax = vmax(bmax, in[idx[i]].p);
            }
            Vec3 ext = bmax - bmin;
            int a = (ext.x >= ext.y && ext.x >= ext.z) ? 0 : (ext.y >= ext.z ? 1 : 2);
            size_t mid = (lo + hi) / 2;
            std::nth_element(idx.begin() + lo, idx.begin() + mid, idx.begin() + hi, [&](uint32_t u, uint32_t v) {
                float pu = in[u].p[a], pv = in[v].p[a];
                return pu < pv || (pu == pv && u < v);
            });
            axis[mid] = uint8_t(a);
            if (par_depth > 0 && hi - lo > 65536) {
                std::thread t([&, lo, mid, par_depth] { run(lo, mid, par_depth - 1); });
                run(mid + 1, hi, par_depth - 1);
                t.join();
                return;
            }
            run(lo, mid, 0);
            lo = mid + 1;
        }
    }
};

inline float dist2(const Vec3& a, const Vec3& b) {
    float dx = a.x - b.x, dy = a.y - b.y, dz = a.z - b.z;
    return dx * dx + dy * dy + dz * dz;
}

// (d2, idx) order: nearer first, then lower index.
inline bool closer(const Neighbour& a, const Neighbour& b) { return a.d2 < b.d2 || (a.d2 == b.d2 && a.idx < b.idx); }

}  // namespace

void PhotonMap::build(std::vector<Photon> photons, int threads, bool keep_ids) {
    if (photons.size() >= (1ull << 32) - 1) throw std::invalid_argument("photon map: at most 2^32 - 2 photons");
    size_t n = photons.size();
    std::vector<uint32_t> idx(n);
    for (size_t i = 0; i < n; ++i) idx[i] = uint32_t(i);
    std::vector<uint8_t> axis(n, 0);
    int par_depth = 0;
    while ((1 << par_depth) < threads && par_depth < 6) ++par_depth;
    Builder b{photons, idx, axis};
    b.run(0, n, par_depth);
    photons_.resize(n);
    for (size_t i = 0; i < n; ++i) {
        photons_[i] = photons[idx[i]];
        photons_[i].flags = (photons_[i].flags & ~3u) | axis[i];
    }
    if (keep_ids)
        ids_ = std::move(idx);
    else
        ids_.clear();
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
            std::pop_heap(out.begin(), out.end(), closer);
            out.back() = nb;
            std::push_heap(out.begin(), out.end(), closer);
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
