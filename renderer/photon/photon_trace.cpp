#include "photon/photon_trace.h"

#include <chrono>

#include "integrators/common.h"
#include "integrators/parallel.h"

namespace rm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

constexpr uint64_t kItemPaths = 1024;  // light paths per work item
constexpr uint64_t kChunkItems = 64;   // items per chunk (a fixed number: the cut is thread-independent)

struct Item {
    std::vector<Photon> photons;
    std::vector<uint32_t> path_end;  // photons stored by the item's paths 0..i (cumulative)
};

// Traces the paths [g0, g0 + n) in items of kItemPaths; returns false on cancel.
bool trace_chunk(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t pass, uint64_t g0,
                 uint64_t n, std::vector<Item>& items, int threads, const std::function<bool()>& poll,
                 std::vector<ThreadStats>& tstats) {
    size_t n_items = size_t((n + kItemPaths - 1) / kItemPaths);
    if (items.size() < n_items) items.resize(n_items);
    std::atomic<bool> cancel{false};
    auto work = [&](size_t i, int t) {
        Item& it = items[i];
        it.photons.clear();
        it.path_end.clear();
        uint64_t a = g0 + i * kItemPaths, b = std::min(g0 + n, a + kItemPaths);
        for (uint64_t g = a; g < b; ++g) {
            trace_photon_path(scene, spec, seed, g, pass, it.photons, tstats[t]);
            it.path_end.push_back(uint32_t(it.photons.size()));
        }
    };
    return run_parallel(threads, n_items, work, poll, cancel);
}

void normalise(std::vector<Photon>& ph, uint64_t paths) {
    if (paths == 0) return;
    float inv = float(1.0 / double(paths));
    for (Photon& p : ph) p.power *= inv;
}

}  // namespace

void trace_photon_path(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t path,
                       uint64_t pass, std::vector<Photon>& out, ThreadStats& stats) {
    Sampler sampler(mix64(seed + 0x70686f746f6eULL + spec.stream), path, pass);
    size_t n = scene.emitters.size();
    // 1. Pick an emitter uniformly and sample a ray of light leaving it
    //    (Jensen 2001, sec. 5.1: emission proportional to power; the
    //    weight carries the flux, Le |cos| / (pdf_a pdf_w) / pick).
    float u_pick = sampler.next_1d();
    Vec2 u_pos = sampler.next_2d();
    float u_extra = sampler.next_1d();
    Vec2 u_dir = sampler.next_2d();
    if (n == 0) return;
    const Emitter& e = *scene.emitters[std::min(size_t(u_pick * float(n)), n - 1)];
    Vec3 center;
    float radius;
    scene.bounding_sphere(center, radius);
    EmissionSample es = e.sample_emission(u_pos, u_extra, u_dir, center, radius);
    if (!(es.pdf_a > 0.f) || !(es.pdf_w > 0.f) || is_black(es.weight)) return;
    Color beta = es.weight * (1.f / emitter_pick_prob(scene));  // flux of the path
    Color thr(1.f);                                              // throughput since the emitter
    Ray ray;
    ray.o = es.p + es.n * es.eps;
    ray.d = es.d;
    BsdfContext ctx{TransportMode::Importance};
    int k = 0;                  // scattering vertices before the current one (null boundaries excluded)
    bool all_specular = true;   // each of them scattered specularly
    for (int depth = 1;; ++depth) {  // segments from the emitter to `it`
        // 2. The next vertex.
        Interaction it;
        ++stats.rays;
        if (!scene.intersect(ray, it)) break;
        const Bsdf& bsdf = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
        Vec3 wi = it.to_local(it.wi);

        // 3. Store a photon where a non-specular lobe can scatter it
        //    (Jensen 2001, sec. 5.2: photons on specular surfaces are useless).
        if (bsdf.has_smooth()) {
            bool direct = k == 0, caustic = k > 0 && all_specular;
            bool keep = spec.caustic_only ? caustic
                        : spec.indirect_only ? !all_specular
                                             : (spec.store_direct || !direct);
            if (keep) {
                Photon ph;
                ph.p = it.p;
                ph.wi = it.wi;
                ph.power = beta * thr;
                ph.flags = (direct ? kPhotonDirect : 0u) | (all_specular ? 0u : kPhotonIndirect) |
                           (uint32_t(std::min(depth, 255)) << kPhotonDepthShift);
                if (is_finite(ph.power) && !is_black(ph.power)) {
                    out.push_back(ph);
                    ++stats.photons;
                }
            }
            // A caustic path ends once it scatters through a non-specular
            // lobe (below, after sampling), not at the first vertex that has
            // one: a BSDF with a delta and a smooth lobe (plastic's coat)
            // passes caustics on through the delta lobe.
        }
        if (spec.max_depth >= 0 && depth >= spec.max_depth) break;

        // 4. Scatter by the adjoint BSDF (importance transport, with the
        //    shading-normal correction of Veach 1997, eq. 5.16).
        BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
        if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) break;
        Vec3 wo = it.to_world(bs.wo);
        thr *= bs.weight * shading_correction(it, it.wi, wo);
        if (bsdf.flags() != kNull) {
            ++k;
            all_specular = all_specular && bs.is_delta;
        }
        if (spec.caustic_only && !all_specular) break;
        ray = it.spawn(wo);

        // 5. Russian roulette (Jensen 2001, sec. 5.1.3; Mitsuba's q = min(max(thr), 0.95)).
        float rr_u = sampler.next_1d();
        if (depth >= spec.rr_depth) {
            float q = std::min(max_component(thr), 0.95f);
            if (!(rr_u < q)) break;
            thr /= q;
        }
    }
}

PhotonPass trace_photons_until(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t target,
                               int threads, const std::function<bool()>& poll, ThreadStats& stats) {
    auto t0 = Clock::now();
    PhotonPass r;
    std::vector<Item> items;
    std::vector<ThreadStats> tstats(threads);
    const uint64_t chunk = kChunkItems * kItemPaths;
    while (r.photons.size() < target) {
        if (!trace_chunk(scene, spec, seed, 0, r.paths, chunk, items, threads, poll, tstats)) {
            r.cancelled = true;
            break;
        }
        // Concatenate in path order, up to the path that stores the target-th photon.
        bool done = false;
        for (size_t i = 0; i < kChunkItems && !done; ++i) {
            const Item& it = items[i];
            uint32_t prev = 0;
            for (size_t j = 0; j < it.path_end.size(); ++j) {
                uint32_t end = it.path_end[j];
                r.photons.insert(r.photons.end(), it.photons.begin() + prev, it.photons.begin() + end);
                prev = end;
                ++r.paths;
                if (r.photons.size() >= target) {
                    done = true;
                    break;
                }
            }
        }
        if (done) break;
        uint64_t found = r.photons.size();
        if (r.paths >= 500000 && (found == 0 || found < r.paths / 1024)) {
            r.target_reached = false;
            break;
        }
    }
    // Photons beyond the target (the last path's) are kept: every photon of
    // a traced path belongs to the estimate.
    for (auto& s : tstats) stats.merge(s);
    normalise(r.photons, r.paths);
    r.seconds = since(t0);
    return r;
}

PhotonPass trace_photon_paths(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t pass,
                              uint64_t paths, int threads, const std::function<bool()>& poll, ThreadStats& stats) {
    auto t0 = Clock::now();
    PhotonPass r;
    std::vector<Item> items;
    std::vector<ThreadStats> tstats(threads);
    const uint64_t chunk = kChunkItems * kItemPaths;
    for (uint64_t g0 = 0; g0 < paths; g0 += chunk) {
        uint64_t n = std::min(chunk, paths - g0);
        if (!trace_chunk(scene, spec, seed, pass, g0, n, items, threads, poll, tstats)) {
            r.cancelled = true;
            break;
        }
        size_t n_items = size_t((n + kItemPaths - 1) / kItemPaths);
        for (size_t i = 0; i < n_items; ++i) r.photons.insert(r.photons.end(), items[i].photons.begin(), items[i].photons.end());
    }
    r.paths = paths;
    for (auto& s : tstats) stats.merge(s);
    normalise(r.photons, r.paths);
    r.seconds = since(t0);
    return r;
}

}  // namespace rm
