#include "transport/photon_trace.h"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>

#include "render/parallel.h"
#include "transport/subpath_walk.h"

namespace rm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

constexpr uint64_t kItemPaths = 1024;  // light paths per work item
constexpr uint64_t kChunkItems = 64;   // items per chunk (a fixed number: the cut is thread-independent)

// The give-up rule. A map stores photons at a rate per light path that only
// tracing reveals, and reaching the target costs target / rate paths. pbrt
// v1's rule (Pharr & Humphreys 2004, sec. 16.5: give up after 500 000 paths
// if fewer than 1 in 1024 stored one) bounds only the rate, so a rate just
// above 1/1024 costs 1024 paths per photon (a minute for a 16 x 16 image at
// 1 spp). Here the paths are bounded, at kPathsPerPhoton per requested
// photon, and tracing gives up early, from kMinPaths on, once even an upper
// confidence bound on the rate (Poisson counts, 6 sigma on the square-root
// scale: a false give-up about 1e-9 per check) is below 1 / kPathsPerPhoton,
// so that a map that cannot reach its target costs about kMinPaths paths,
// not the bound. A map cut short keeps its photons, their power divided by
// the paths traced: fewer photons, a noisier and blurrier estimate
// (reported), not a wrong one. 512 is twice the paths per photon of the
// canonical scenes' sparsest map (translucent_object's caustic map, 1 in
// 258; docs/photon_give_up.md), whose renders are unchanged by the rule.
constexpr uint64_t kPathsPerPhoton = 512;
// Paths traced before giving up in any case (about pbrt's 500 000, a whole
// number of chunks): a small map is not cut short by chance.
constexpr uint64_t kMinPaths = 8 * kChunkItems * kItemPaths;

// Whether `stored` photons in `paths` paths show, beyond chance, a rate
// below 1 / kPathsPerPhoton.
bool rate_too_low(uint64_t stored, uint64_t paths) {
    const double hi = std::sqrt(double(stored)) + 3.0;  // sqrt of a Poisson count: sd 1/2, so 6 sd
    return hi * hi * double(kPathsPerPhoton) < double(paths);
}

struct Item {
    std::vector<Photon> photons;
    std::vector<uint32_t> path_end;  // photons stored by the item's paths 0..i (cumulative)
};

// The light walk's vertices for trace_photon_path, one buffer per thread.
std::vector<PathVertex>& light_scratch() {
    thread_local std::vector<PathVertex> v;
    return v;
}

// Photon storage (Jensen 2001, sec. 5.2), a visitor on the vertices of the
// light walk (subpath.h), which brings the emitter pick, the emission
// sample, the adjoint BSDFs, free flights through media, index-matched
// boundaries and Russian roulette. The visitor decides what each vertex
// leaves and where the path may end, from the vertices before it:
//   surface photons (not spec.volume) at vertices with a non-specular lobe
//   (photons on specular surfaces are useless), filtered by the spec: L S+
//   D only (caustic_only), or only after a non-specular vertex
//   (indirect_only), or all but the first vertex's (store_direct off);
//   volume photons (spec.volume) at medium scattering events after at least
//   one scattering vertex (L X+ V), with the power the walk carries there,
//   which already holds the event's sigma_s / (density of scattering there)
//   (free_flight_*), so the photons are distributed with density
//   sigma_s(x) int L(x, w) dw per unit volume (the seed: d^2 Phi = sigma_s
//   L dw dV, Jensen & Christensen 1998): what the camera pass's
//   Phi / (4/3 pi r^3) estimate divides by volume.
// A photon's depth is its vertex's index on the walk: segments from the
// emitter without media, scattering vertices through them.
class PhotonStore {
public:
    PhotonStore(const PhotonTraceSpec& spec, std::vector<Photon>& out, ThreadStats& stats)
        : out_(out),
          stats_(stats),
          caustic_only_(spec.caustic_only),
          volume_(spec.volume),
          keep_(spec.caustic_only    ? kKeepCaustic
                : spec.indirect_only ? kKeepIndirect
                                     : (spec.store_direct ? kKeepAll : kKeepAll & ~kKeepDirect)) {}

    // The walk's window mode (subpath_walk.h): vertex n and its predecessor.
    static constexpr bool kLastTwo = true;

    // A new light path: no vertex before the next one.
    void start_path() {
        k_ = 0;
        all_specular_ = true;
        medium_flags_ = 0;
    }

    bool operator()(const PathVertex& v, const PathVertex* prev_vertex, int n) {
        if (n == 0) return true;  // y0: the emission sample leaves no photon
        // 1. The vertex before this one is complete now (its lobe is known): count it.
        if (n >= 2) {
            const PathVertex& prev = *prev_vertex;
            if (prev.type == VType::Medium) {
                ++k_;
                all_specular_ = false;
                medium_flags_ |= prev.enclosed ? kPhotonSubsurfacePath : kPhotonVolumePath;
            } else if (!prev.null_surface()) {
                ++k_;
                all_specular_ = all_specular_ && prev.delta;
            }
        }
        // A caustic path ends once it scattered through a non-specular lobe.
        if (caustic_only_ && !all_specular_) return false;
        const uint32_t depth = uint32_t(std::min(n, 255)) << kPhotonDepthShift;
        // 2. A volume photon at a multiple-scattering event (k > 0); a
        //    medium vertex ends a caustic path.
        if (v.type == VType::Medium) {
            if (volume_ && k_ > 0) store(v, kPhotonIndirect | depth | (uint32_t(v.medium + 1) << kPhotonMediumShift));
            return !caustic_only_;
        }
        // 3. A surface photon where a non-specular lobe can scatter it: the
        //    spec's choice by the path so far (keep_).
        if (!volume_ && v.bsdf->has_smooth()) {
            const bool direct = k_ == 0;
            if (keep_ & (direct ? kKeepDirect : all_specular_ ? kKeepCausticPath : kKeepIndirectPath))
                store(v,
                      (direct ? kPhotonDirect : 0u) | (all_specular_ ? 0u : kPhotonIndirect) | medium_flags_ | depth);
        }
        // 4. A caustic path goes on only through a delta lobe (a BSDF with a
        //    delta and a smooth lobe, plastic's coat, passes caustics on
        //    through the delta one: step 1 at the next vertex decides).
        return !caustic_only_ || (v.bsdf->flags() & kDelta);
    }

private:
    // The paths whose photons the spec keeps, by the scattering vertices
    // before the photon: none (direct), all specular (caustic), or not.
    static constexpr uint8_t kKeepDirect = 1, kKeepCausticPath = 2, kKeepIndirectPath = 4;
    static constexpr uint8_t kKeepAll = kKeepDirect | kKeepCausticPath | kKeepIndirectPath;
    static constexpr uint8_t kKeepCaustic = kKeepCausticPath;    // L S+ D
    static constexpr uint8_t kKeepIndirect = kKeepIndirectPath;  // a non-specular vertex before

    void store(const PathVertex& v, uint32_t flags) {
        if (!is_finite(v.beta) || is_black(v.beta)) return;
        Photon& ph = out_.emplace_back();  // written in place (no temporary copied)
        ph.p = v.it.p;
        ph.wi = v.it.wi;
        ph.power = v.beta;
        ph.flags = flags;
        ++stats_.photons;
    }

    std::vector<Photon>& out_;
    ThreadStats& stats_;
    const bool caustic_only_, volume_;
    const uint8_t keep_;
    int k_ = 0;                  // scattering vertices before the current one (null boundaries excluded)
    bool all_specular_ = true;   // each of them scattered specularly
    uint32_t medium_flags_ = 0;  // kPhotonVolumePath / kPhotonSubsurfacePath once the path scattered in a medium
};

// Traces light paths [g0, g1) of pass `pass` into `out` (path_end, when
// given, gets the photon count after each path), with the walk compiled
// for media or without them (kMedia: the scene has media), on the same
// random stream either way.
template <bool kMedia>
void trace_paths(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t pass, uint64_t g0,
                 uint64_t g1, std::vector<Photon>& out, std::vector<uint32_t>* path_end, ThreadStats& stats,
                 std::vector<PathVertex>& light) {
    const uint64_t stream = mix64(seed + 0x70686f746f6eULL + spec.stream);
    // A photon of depth d is vertex y_d: max_depth segments are max_depth + 1 vertices.
    const int max_vertices = spec.max_depth < 0 ? INT_MAX : spec.max_depth + 1;
    PhotonStore store(spec, out, stats);
    for (uint64_t g = g0; g < g1; ++g) {
        store.start_path();
        EmissionSample es;
        if constexpr (kMedia) {
            Sampler sampler(stream, g, pass);
            light_subpath_with(scene, sampler, max_vertices, spec.rr_depth, light, es, stats, store, false);
        } else {
            IndependentSampler sampler(stream, g, pass);
            light_subpath_with<false>(scene, sampler, max_vertices, spec.rr_depth, light, es, stats, store, false);
        }
        if (path_end) path_end->push_back(uint32_t(out.size()));
    }
}

// Traces the paths [g0, g0 + n) in items of kItemPaths; returns false on cancel.
bool trace_chunk(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t pass, uint64_t g0, uint64_t n,
                 std::vector<Item>& items, int threads, const std::function<bool()>& poll,
                 std::vector<ThreadStats>& tstats) {
    size_t n_items = size_t((n + kItemPaths - 1) / kItemPaths);
    if (items.size() < n_items) items.resize(n_items);
    std::atomic<bool> cancel{false};
    auto work = [&](size_t i, int t) {
        Item& it = items[i];
        it.photons.clear();
        it.path_end.clear();
        uint64_t a = g0 + i * kItemPaths, b = std::min(g0 + n, a + kItemPaths);
        std::vector<PathVertex> light;  // the walk's two slots, one buffer per item
        if (scene.features.has_media)
            trace_paths<true>(scene, spec, seed, pass, a, b, it.photons, &it.path_end, tstats[t], light);
        else
            trace_paths<false>(scene, spec, seed, pass, a, b, it.photons, &it.path_end, tstats[t], light);
    };
    return run_parallel(threads, n_items, work, poll, cancel);
}

void normalise(std::vector<Photon>& ph, uint64_t paths) {
    if (paths == 0) return;
    float inv = float(1.0 / double(paths));
    for (Photon& p : ph) p.power *= inv;
}

}  // namespace

void trace_photon_path(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t path, uint64_t pass,
                       std::vector<Photon>& out, ThreadStats& stats) {
    if (scene.features.has_media)
        trace_paths<true>(scene, spec, seed, pass, path, path + 1, out, nullptr, stats, light_scratch());
    else
        trace_paths<false>(scene, spec, seed, pass, path, path + 1, out, nullptr, stats, light_scratch());
}

uint64_t photon_path_bound(uint64_t target) {
    return target > UINT64_MAX / kPathsPerPhoton ? UINT64_MAX : std::max(kMinPaths, kPathsPerPhoton * target);
}

PhotonPass trace_photons_until(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t target,
                               int threads, const std::function<bool()>& poll, ThreadStats& stats) {
    auto t0 = Clock::now();
    PhotonPass r;
    r.max_paths = photon_path_bound(target);
    std::vector<Item> items;
    std::vector<ThreadStats> tstats(threads);
    const uint64_t chunk = kChunkItems * kItemPaths;
    PollGate gate(poll);
    while (r.photons.size() < target) {
        const uint64_t n = std::min(chunk, r.max_paths - r.paths);
        if (!gate() || !trace_chunk(scene, spec, seed, 0, r.paths, n, items, threads, poll, tstats)) {
            r.cancelled = true;
            break;
        }
        // Concatenate in path order, up to the path that stores the target-th photon.
        bool done = false;
        const size_t n_items = size_t((n + kItemPaths - 1) / kItemPaths);
        for (size_t i = 0; i < n_items && !done; ++i) {
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
        if (r.paths >= r.max_paths || (r.paths >= kMinPaths && rate_too_low(r.photons.size(), r.paths))) {
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
                              uint64_t paths, int threads, const std::function<bool()>& poll, ThreadStats& stats,
                              uint64_t max_photons, std::vector<Photon> storage) {
    auto t0 = Clock::now();
    PhotonPass r;
    r.photons = std::move(storage);
    r.photons.clear();
    std::vector<Item> items;
    std::vector<ThreadStats> tstats(threads);
    const uint64_t chunk = kChunkItems * kItemPaths;
    PollGate gate(poll);
    for (uint64_t g0 = 0; g0 < paths; g0 += chunk) {
        uint64_t n = std::min(chunk, paths - g0);
        if (!gate() || !trace_chunk(scene, spec, seed, pass, g0, n, items, threads, poll, tstats)) {
            r.cancelled = true;
            break;
        }
        size_t n_items = size_t((n + kItemPaths - 1) / kItemPaths);
        for (size_t i = 0; i < n_items; ++i)
            r.photons.insert(r.photons.end(), items[i].photons.begin(), items[i].photons.end());
        if (r.photons.size() > max_photons) {
            r.over_memory = true;
            break;
        }
    }
    r.paths = paths;
    for (auto& s : tstats) stats.merge(s);
    normalise(r.photons, r.paths);
    r.seconds = since(t0);
    return r;
}

}  // namespace rm
