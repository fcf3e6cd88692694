#include "transport/photon_trace.h"

#include <chrono>

#include "transport/common.h"
#include "transport/media_common.h"
#include "render/parallel.h"

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


// The shape an area emitter lies on (-1 for the others): where its light
// starts decides the medium it starts in (emitter_medium).
int emitter_shape_of(const Scene& scene, const Emitter& e) {
    for (size_t i = 0; i < scene.shapes.size(); ++i) {
        int k = scene.shapes[i]->emitter;
        if (k >= 0 && scene.emitters[k].get() == &e) return int(i);
    }
    return -1;
}

Photon make_photon(const Vec3& p, const Vec3& wi, const Color& power, uint32_t flags) {
    Photon ph;
    ph.p = p;
    ph.wi = wi;
    ph.power = power;
    ph.flags = flags;
    return ph;
}

// Photon tracing through participating media (photon_trace.h): the walk of
// subpath.cpp's random_walk for light subpaths, storing photons instead of
// vertices. Surface photons follow the rules of trace_photon_path; volume
// photons (spec.volume) are stored at medium scattering events, with the
// power th.beta the walk carries there. That power already holds the
// event's sigma_s / (density of scattering there) (free_flight_*), so the
// stored photons are distributed with density sigma_s(x) int L(x, w) dw per
// unit volume (the seed: d^2 Phi = sigma_s L dw dV, Jensen & Christensen 1998):
// what the camera pass's Phi / (4/3 pi r^3) estimate divides by volume.
void trace_media_path(const Scene& scene, const PhotonTraceSpec& spec, const Emitter& e, const EmissionSample& es,
                      const Color& beta0, Sampler& sampler, std::vector<Photon>& out, ThreadStats& stats) {
    Ray ray;
    ray.o = es.p + es.n * es.eps;
    ray.d = es.d;
    MediumTracker mt = emitter_medium(scene, ray, es.n, emitter_shape_of(scene, e));
    // Hero channel of spectral MIS, drawn once per light path (media_common.h).
    SpectralThroughput th(std::min(int(sampler.next_1d() * 3.f), 2),
                          e.is_infinite() ? beta0 * transmittance_from_infinity(scene, mt.medium) : beta0);
    if (is_black(th.beta)) return;  // light from infinity that no unbounded medium lets through
    const float b0 = max_component(beta0);
    BsdfContext ctx{TransportMode::Importance};
    int k = 0;                 // scattering vertices before the current one
    bool all_specular = true;  // each of them scattered specularly
    uint32_t medium_flags = 0; // kPhotonVolumePath / kPhotonSubsurfacePath once it scattered in a medium
    // volpath's roulette (volpath.cpp says why): only once the throughput
    // fell below its start, capped at 0.95 beyond kLongWalk events.
    constexpr int kLongWalk = 1024;
    auto roulette = [&](int depth, float rr_u) {
        if (depth < spec.rr_depth) return true;
        float q = b0 > 0.f ? max_component(th.beta) / b0 : 0.f;
        if (depth >= kLongWalk) q = std::min(q, 0.95f);
        if (q >= 1.f) return true;
        if (!(rr_u < q)) return false;
        th.beta /= q;
        return true;
    };
    auto store = [&](const Vec3& p, const Vec3& wi, uint32_t flags) {
        if (!is_finite(th.beta) || is_black(th.beta)) return;
        out.push_back(make_photon(p, wi, th.beta, flags));
        ++stats.photons;
    };
    for (int depth = 1, guard = 0; guard < (1 << 20); ++guard) {  // depth: scattering vertex about to be made
        Interaction it;
        ++stats.rays;
        bool hit = scene.intersect(ray, it);
        // 1. Free flight through the current medium.
        if (mt.medium >= 0) {
            const Medium& med = *scene.media[mt.medium];
            float t = 0.f;
            FlightEvent event = free_flight(med, ray, hit ? it.t : ray.tmax, sampler, th, t);
            if (event == kAbsorbed) break;
            if (event == kScattered) {
                Vec3 p = ray.o + ray.d * t;
                // 2. A volume photon at a multiple-scattering event (k > 0).
                if (spec.volume && k > 0)
                    store(p, -ray.d, kPhotonIndirect | (uint32_t(std::min(depth, 255)) << kPhotonDepthShift) |
                                         (uint32_t(mt.medium + 1) << kPhotonMediumShift));
                ++k;
                all_specular = false;
                medium_flags |= mt.enclosed ? kPhotonSubsurfacePath : kPhotonVolumePath;
                if (spec.caustic_only) break;  // L S+ D only: a medium vertex ends a caustic path
                if (spec.max_depth >= 0 && depth >= spec.max_depth) break;
                PhaseSample ps = med.phase->sample(-ray.d, sampler.next_2d());
                if (!(ps.pdf_w > 0.f)) break;
                th.beta *= ps.weight;
                ray = Ray{p, ps.wo, 0.f, kInf};
                if (!roulette(depth++, sampler.next_1d())) break;
                continue;
            }
        }
        if (!hit) break;
        const Bsdf& bsdf = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
        // 3. An index-matched boundary: no vertex, only a change of medium.
        if (bsdf.flags() == kNull) {
            mt.cross(it, ray.d, true);
            ray = it.spawn(ray.d);
            continue;
        }
        // 4. A surface photon where a non-specular lobe can scatter it
        //    (as trace_photon_path; none in a volume-only pass).
        if (!spec.volume && bsdf.has_smooth()) {
            bool direct = k == 0, caustic = k > 0 && all_specular;
            bool keep = spec.caustic_only ? caustic : spec.indirect_only ? !all_specular : (spec.store_direct || !direct);
            if (keep)
                store(it.p, it.wi, (direct ? kPhotonDirect : 0u) | (all_specular ? 0u : kPhotonIndirect) |
                                       medium_flags | (uint32_t(std::min(depth, 255)) << kPhotonDepthShift));
        }
        if (spec.max_depth >= 0 && depth >= spec.max_depth) break;
        // 5. Scatter by the adjoint BSDF; the medium changes when the sample crosses a boundary.
        Vec3 wi = it.to_local(it.wi);
        BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
        if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) break;
        Vec3 wo = it.to_world(bs.wo);
        th.beta *= bs.weight * shading_correction(it, it.wi, wo);
        ++k;
        all_specular = all_specular && bs.is_delta;
        if (spec.caustic_only && !all_specular) break;
        mt.cross(it, wo, false);
        ray = it.spawn(wo);
        if (!roulette(depth++, sampler.next_1d())) break;
    }
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
    if (scene.features.has_media) {
        trace_media_path(scene, spec, e, es, beta, sampler, out, stats);
        return;
    }
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
