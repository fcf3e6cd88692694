// What the caching estimators (irrcache.cpp, radcache.cpp) share: the
// record index, the path tracers they run (the camera path without its
// indirect class, and the gather rays' radiance), and the deterministic
// overture that fills a cache before the camera passes (irrcache.cpp's
// first comment).
#pragma once
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <vector>

#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/camera_sample.h"

namespace rm {

// Random streams of the overture (pixel index, one of these sample indices):
// far from the camera passes' sample indices.
constexpr uint64_t kCandidateSample = uint64_t(1) << 62;
constexpr uint64_t kRecordSample = kCandidateSample + 1;
constexpr int kOvertureBatch = 256;
constexpr int kMaxChain = 8;  // delta vertices a gather ray follows to its first smooth vertex

// The record index: a small loose octree of our own (after pbrt-v2's
// irradiance cache octree: a record's sphere of influence is stored in the
// nodes it overlaps down to its own size; a lookup walks one root-to-leaf
// path). About 100 lines, built single-threaded and read concurrently, where
// a general spatial library would bring a dependency for one use.
class RecordOctree {
public:
    void reset(const Vec3& center, float half) {
        lo_ = center - Vec3(half);
        size_ = 2.f * half;
        nodes_.assign(1, Node());
    }
    void insert(int rec, const Vec3& p, float reach) { insert(0, lo_, size_, rec, p, reach, 0); }
    // f(record index) for every record stored on the path to x's leaf.
    template <class F>
    void lookup(const Vec3& x, F&& f) const {
        int node = 0;
        Vec3 lo = lo_;
        float size = size_;
        for (;;) {
            for (int r : nodes_[size_t(node)].items) f(r);
            float h = 0.5f * size;
            int c = (x.x >= lo.x + h ? 1 : 0) | (x.y >= lo.y + h ? 2 : 0) | (x.z >= lo.z + h ? 4 : 0);
            int next = nodes_[size_t(node)].child[c];
            if (next < 0) return;
            lo = child_lo(lo, h, c);
            size = h;
            node = next;
        }
    }
    // f(record index) for every record stored in a node the sphere (c, r)
    // overlaps (a record may come more than once).
    template <class F>
    void query_sphere(const Vec3& c, float r, F&& f) const {
        sphere(0, lo_, size_, c, r, f);
    }

private:
    struct Node {
        int child[8] = {-1, -1, -1, -1, -1, -1, -1, -1};
        std::vector<int> items;
    };
    static Vec3 child_lo(const Vec3& lo, float h, int c) {
        return Vec3(lo.x + ((c & 1) ? h : 0.f), lo.y + ((c & 2) ? h : 0.f), lo.z + ((c & 4) ? h : 0.f));
    }
    static bool overlaps(const Vec3& lo, float size, const Vec3& c, float r) {
        float d2 = 0.f;
        for (int a = 0; a < 3; ++a) {
            float v = c[a] < lo[a] ? lo[a] - c[a] : (c[a] > lo[a] + size ? c[a] - lo[a] - size : 0.f);
            d2 += v * v;
        }
        return d2 <= r * r;
    }
    void insert(int node, Vec3 lo, float size, int rec, const Vec3& p, float reach, int depth) {
        // Stored here once the node is no larger than the sphere's box.
        if (size <= 2.f * reach || depth >= 20) {
            nodes_[size_t(node)].items.push_back(rec);
            return;
        }
        float h = 0.5f * size;
        for (int c = 0; c < 8; ++c) {
            Vec3 clo = child_lo(lo, h, c);
            if (!overlaps(clo, h, p, reach)) continue;
            int next = nodes_[size_t(node)].child[c];
            if (next < 0) {
                next = int(nodes_.size());
                nodes_[size_t(node)].child[c] = next;
                nodes_.emplace_back();
            }
            insert(next, clo, h, rec, p, reach, depth + 1);
        }
    }
    template <class F>
    void sphere(int node, Vec3 lo, float size, const Vec3& c, float r, F& f) const {
        if (!overlaps(lo, size, c, r)) return;
        for (int i : nodes_[size_t(node)].items) f(i);
        float h = 0.5f * size;
        for (int k = 0; k < 8; ++k)
            if (nodes_[size_t(node)].child[k] >= 0)
                sphere(nodes_[size_t(node)].child[k], child_lo(lo, h, k), h, c, r, f);
    }
    std::vector<Node> nodes_;
    Vec3 lo_;
    float size_ = 1.f;
};

struct CacheStats {
    uint64_t candidates = 0, computed = 0;
    double overture_seconds = 0;
    std::atomic<uint64_t> misses{0}, lookups{0};
    void reset() {
        candidates = computed = 0;
        overture_seconds = 0;
        misses = 0;
        lookups = 0;
    }
};

// The `path` runs of a caching estimator: camera_all (every class: where x
// takes nothing from the cache), camera_direct (all but indirect), and the
// gather rays' from their first smooth vertex y, one per length of the delta
// chain before y (max_depth counts from the camera: the camera segment and
// the chain come first).
struct CachePaths {
    CachePaths(int max_depth, int rr_depth, bool hide) : max_depth_(max_depth) {
        auto make_path = [&](int md, bool h) {
            IntegratorDesc d;
            d.type = "path";
            d.params.set("max_depth", int64_t(md));
            d.params.set("rr_depth", int64_t(rr_depth));
            d.params.set("hide_emitters", h);
            // No truncation probe: its tally would count the gather paths
            // as camera samples, and the camera path's lacks the cached class.
            d.params.set("truncation_probe", 0.0);
            return make_integrator(d, all_effects());
        };
        camera_all = make_path(max_depth, hide);
        camera_direct = make_path(max_depth, hide);
        for (int c = 0; c <= kMaxChain; ++c) {
            int md = max_depth < 0 ? -1 : std::max(1, max_depth - 1 - c);
            gather.push_back(make_path(md, false));
            gather.back()->mask = effect_mask({kDirect, kCaustic, kIndirect});
            gather_ok.push_back(max_depth < 0 || max_depth - 1 - c >= 2);
        }
    }
    void set_masks(const EffectMask& mask) const {
        camera_all->mask = mask;
        EffectMask m = mask;
        m[kIndirect] = false;
        camera_direct->mask = m;
    }
    // Radiance of class "light that scattered at a smooth vertex after x"
    // arriving at x from direction d; `dist`: the first hit's distance (inf
    // when the ray leaves the scene).
    Color gather_radiance(const Scene& scene, Sampler& sampler, const Interaction& x, const Vec3& d, float& dist,
                          ThreadStats& stats) const {
        dist = kInf;
        if (dot(d, x.n) <= 0.f) return Color(0.f);  // below the geometric surface
        Ray ray = x.spawn(d);
        Color w(1.f);
        BsdfContext ctx;
        for (int c = 0; c <= kMaxChain; ++c) {
            Interaction h;
            ++stats.rays;
            if (!scene.intersect(ray, h)) return Color(0.f);
            if (c == 0) dist = h.t;
            const Bsdf& b = *scene.bsdfs[scene.shapes[h.shape]->bsdf];
            if (b.has_smooth()) {
                if (!gather_ok[size_t(c)]) return Color(0.f);
                EffectRadiance er;
                gather[size_t(c)]->sample(scene, sampler, ray, er, stats);
                return w * er.total();
            }
            ctx.set(h);
            BsdfSample bs = b.sample(ctx, h.to_local(h.wi), sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight) || !bs.is_delta) return Color(0.f);
            w *= bs.weight;
            ray = h.spawn(h.to_world(bs.wo));
        }
        return Color(0.f);
    }
    // The camera side of a caching estimator's radiance(): intersects `ray`
    // into `x`; where x takes its indirect light from the cache (the class
    // asked for and cacheable(x)) runs camera_direct and returns true (the
    // caller adds the cache's part), else camera_all and false.
    template <class F>
    bool camera(const Scene& scene, Sampler& sampler, const Ray& ray, const EffectMask& mask, F&& cacheable,
                Interaction& x, EffectRadiance& out, ThreadStats& stats) const {
        ++stats.rays;
        bool hit = scene.intersect(ray, x);
        bool cached = hit && mask[kIndirect] && cacheable(static_cast<const Interaction&>(x));
        (cached ? camera_direct : camera_all)->sample(scene, sampler, ray, out, stats);
        return cached;
    }
    // The factories' check of min_spacing <= max_spacing.
    static void check_spacing(ParamReader& p, float min_spacing, float max_spacing) {
        if (min_spacing > max_spacing)
            p.fail("min_spacing", "min_spacing (" + std::to_string(min_spacing) + ") exceeds max_spacing (" +
                                      std::to_string(max_spacing) + ")");
    }
    // Whether paths of 3 segments (camera, x, y) are allowed at all.
    bool indirect_possible() const { return max_depth_ < 0 || max_depth_ >= 3; }

    std::unique_ptr<Integrator> camera_all, camera_direct;
    std::vector<std::unique_ptr<Integrator>> gather;
    std::vector<bool> gather_ok;

private:
    int max_depth_;
};

// The overture: candidates are the first hits of one camera ray per pixel
// of the crop window (stream kCandidateSample), in coarse-to-fine grids
// (stride 16, 8, 4, 2, 1; each pixel once), in batches of kOvertureBatch.
// In a batch, for each candidate x with wanted(x) (cacheable and not yet
// covered), compute(i, x, sampler, stats) makes record i on the stream
// kRecordSample of its pixel, in parallel; then commit(i) inserts the
// batch's records in candidate order. False when cancelled.
template <class Wanted, class Compute, class Commit>
bool run_overture(PassLoop& loop, CacheStats& cs, Wanted&& wanted, Compute&& compute, Commit&& commit) {
    const Scene& scene = loop.scene();
    const Sensor& sensor = *scene.sensor;
    const int W = sensor.width;
    std::vector<int> cand;
    const int cx = sensor.crop_x, cy = sensor.crop_y, cw = sensor.crop_w, ch = sensor.crop_h;
    for (int s = 16; s >= 1; s /= 2)
        for (int y = 0; y < ch; y += s)
            for (int x = 0; x < cw; x += s) {
                bool coarser = s < 16 && (x % (2 * s) == 0) && (y % (2 * s) == 0);
                if (!coarser) cand.push_back((cy + y) * W + (cx + x));
            }
    cs.candidates = cand.size();
    FilterSampler filter(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev);
    std::vector<char> made(kOvertureBatch);
    for (size_t b0 = 0; b0 < cand.size(); b0 += kOvertureBatch) {
        const size_t n = std::min(cand.size() - b0, size_t(kOvertureBatch));
        std::fill(made.begin(), made.end(), 0);
        bool done = loop.parallel_for(n, [&](size_t i, int t) {
            ThreadStats& stats = loop.stats(t);
            const int pixel = cand[b0 + i];
            Sampler csamp(loop.seed(), uint64_t(pixel), kCandidateSample);
            SensorRay sr = sample_camera_ray(sensor, filter, pixel, csamp);
            Interaction it;
            ++stats.rays;
            if (!scene.intersect(sr.ray, it) || !wanted(static_cast<const Interaction&>(it))) return;
            Sampler rs(loop.seed(), uint64_t(pixel), kRecordSample);
            compute(i, static_cast<const Interaction&>(it), rs, stats);
            made[i] = 1;
        });
        if (!done) return false;
        for (size_t i = 0; i < n; ++i)
            if (made[i]) {
                commit(i);
                ++cs.computed;
            }
    }
    return true;
}

// The camera passes of a caching estimator C (its radiance()), through the
// camera driver.
template <class C>
class CachePass final : public Integrator {
public:
    explicit CachePass(const C& c) : c_(c) {
        type = c.type;
        caps = c.caps;
        caps.driver = Driver::Camera;
        mask = c.mask;
    }
    void sample(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out,
                ThreadStats& stats) const override {
        c_.radiance(scene, sampler, ray, out, stats);
    }

private:
    const C& c_;
};

// One render of a caching estimator: reset(center, radius) empties its cache
// for the scene's bounding sphere; when `fill`, overture(loop) fills it (the
// loop's setup: its time counts against a time budget); then the camera
// passes read it.
template <class C, class Reset, class Overture>
RenderOutput drive_cache(const C& c, const Scene& scene, const RenderOptions& opts, const PollFn& poll, CacheStats& cs,
                         bool fill, Reset&& reset, Overture&& overture) {
    Vec3 center;
    float radius;
    scene.bounding_sphere(center, radius);
    reset(center, radius);
    cs.reset();
    PassLoop loop(scene, opts, poll);
    auto t0 = std::chrono::steady_clock::now();
    if (fill && !overture(loop)) return loop.cancelled_output();
    cs.overture_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    CachePass<C> pass(c);
    RenderOutput out = render_camera_paths(loop, pass);
    out.seconds = loop.elapsed();
    return out;
}

}  // namespace rm
