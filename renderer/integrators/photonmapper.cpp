// `photonmapper`: two-pass photon mapping (Jensen 1996, "Global Illumination
// using Photon Maps"; Jensen 2001, "Realistic Image Synthesis Using Photon
// Mapping", ch. 9). Pass 1 traces photons into a caustic map (L S+ D paths
// only) and a global map; pass 2 traces camera rays and splits the radiance
// reflected at the first non-specular vertex x four ways (Jensen 2001, eq.
// 9.6; the seed lecture's "integral evaluation (2)"):
//   direct    light reaching x straight from an emitter: next event estimation
//             (direct_samples shadow rays, light sampling only);
//   specular  what x's delta lobes reflect: Monte Carlo ray tracing, the camera
//             path continuing through mirrors and glass;
//   caustics  light reaching x through specular vertices only: the caustic
//             map's radiance estimate at x;
//   indirect  light reaching x after a non-specular bounce: final gathering,
//             gather_rays BSDF samples from x whose first non-specular hit x'
//             reads the global map's estimate of the radiance x' reflects
//             (all photons at x': its direct, caustic and indirect light);
//             with final_gather off the global map (then holding only photons
//             that arrived after a non-specular bounce) is read at x itself,
//             which shows the density estimate's bias directly.
// The radiance estimate (Jensen 2001, eq. 7.6):
//   L(x, w) ~ sum_{p=1..n} f_r(x, w_p, w) Phi_p / (pi r^2),
// over the n = lookup_size nearest photons within the maximum radius, r the
// distance to the n-th (or the maximum radius when fewer are found).
// Effect classes: direct -> `direct`, caustic map -> `caustic`, global map ->
// `indirect`, all three filed under `specular` when the camera path reached x
// through a specular vertex, emission -> `emission` (DESIGN section 3).
//
// Parameters (Mitsuba 0.6's photonmapper names in snake_case; radii relative
// to the radius of the scene's bounding sphere, as Mitsuba's are relative to
// the scene size):
//   direct_samples         shadow rays per camera sample at x (directSamples, 16)
//   global_photons         photons stored in the global map (globalPhotons, 250000)
//   caustic_photons        photons stored in the caustic map (causticPhotons, 250000)
//   global_lookup_radius   maximum lookup radius, global map (globalLookupRadius, 0.05)
//   caustic_lookup_radius  maximum lookup radius, caustic map (causticLookupRadius, 0.0125)
//   lookup_size            photons per radiance estimate, n (lookupSize, 120)
//   gather_rays            final-gathering rays per camera sample (ours, 32)
//   final_gather           false: the global map seen directly at x (ours, true)
//   max_depth, rr_depth, hide_emitters   as in `path` (maxDepth, rrDepth, hideEmitters)
//   (granularity, Mitsuba's work-unit size, is accepted and ignored.)
// max_depth bounds whole paths: a photon of depth d (segments from its
// emitter, photon_trace.h) is read at a vertex c segments from the camera
// only when d + c <= max_depth.
//
// Only what the scene calls for (DESIGN section 3): no caustic map unless
// the scene has both specular and non-specular surfaces and the caustic or
// specular class is simulated; no global map unless the indirect class (or
// the specular class, through specular surfaces) is. res.stats["photon_maps"]
// lists the maps built.
//
// Bias: the estimate blurs the photon density over the disc of radius r (and
// counts photons of nearby surfaces: corners read brighter), and n / (pi r_n^2)
// itself overestimates a Poisson density by n / (n - 1) (the n-th photon
// sits on the disc's rim); it vanishes as the photon count grows with
// n -> inf, n / N -> 0 (Jensen 2001, sec. 7.2). Measured per scene and effect
// in benchmarks/photon_bias.py; sppm is the consistent form.
#include <chrono>
#include <limits>
#include <stdexcept>
#include <thread>

#include "integrators/common.h"
#include "integrators/render.h"
#include "photon/photon_trace.h"

namespace rm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct Maps {
    PhotonMap caustic, global;
    bool has_caustic = false, has_global = false;
    float r2_caustic = 0.f, r2_global = 0.f;
};

// Photons of depth d may be read c segments from the camera when d + c <= max_depth.
inline int photon_budget(int max_depth, int camera_segments) {
    return max_depth < 0 ? 255 : std::min(255, max_depth - camera_segments);
}

}  // namespace

class PhotonMapper final : public Integrator {
public:
    explicit PhotonMapper(const IntegratorDesc& d)
        : max_depth_(d.max_depth), rr_depth_(d.rr_depth), hide_(d.hide_emitters), direct_samples_(d.direct_samples),
          global_photons_(d.global_photons), caustic_photons_(d.caustic_photons),
          global_radius_(d.global_lookup_radius), caustic_radius_(d.caustic_lookup_radius),
          lookup_size_(d.lookup_size), gather_rays_(d.gather_rays), final_gather_(d.final_gather) {
        auto bad = [](const std::string& p, const std::string& what) {
            throw std::invalid_argument("integrator 'photonmapper': " + p + " " + what);
        };
        if (direct_samples_ < 0) bad("direct_samples", "must be >= 0");
        if (global_photons_ < 0) bad("global_photons", "must be >= 0");
        if (caustic_photons_ < 0) bad("caustic_photons", "must be >= 0");
        if (!(global_radius_ > 0.f) || !std::isfinite(global_radius_)) bad("global_lookup_radius", "must be > 0");
        if (!(caustic_radius_ > 0.f) || !std::isfinite(caustic_radius_)) bad("caustic_lookup_radius", "must be > 0");
        if (lookup_size_ < 1) bad("lookup_size", "must be >= 1");
        if (gather_rays_ < 1) bad("gather_rays", "must be >= 1");
    }

    bool owns_driver() const override { return true; }
    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'photonmapper' renders through its own driver");
    }

    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    // Pass 2: the radiance along one camera ray, split four ways (top of file).
    void radiance(const Scene& scene, const Maps& maps, Sampler& sampler, const Ray& camera_ray, EffectRadiance& out,
                  ThreadStats& stats) const {
        thread_local std::vector<Neighbour> nb;
        Ray ray = camera_ray;
        Color beta(1.f);
        PathClass pc;
        BsdfContext ctx;
        for (int depth = 0;; ++depth) {
            // 1. The next vertex, and emission it shows (reached from the camera
            //    directly or through specular vertices only).
            Interaction it;
            int cls = pc.classify();
            if (!trace_counting_emission(scene, ray, it, beta, cls, !(depth == 0 && hide_) && mask[cls], out, stats))
                break;
            const Shape& shape = *scene.shapes[it.shape];
            if (max_depth_ >= 0 && depth + 1 >= max_depth_) break;
            const Bsdf& bsdf = *scene.bsdfs[shape.bsdf];
            Vec3 wi = it.to_local(it.wi);
            const int c = depth + 1;  // segments from the camera to x
            const bool via_specular = pc.scatter_vertices > 0;

            if (bsdf.has_smooth()) {
                // 2. Direct light by ray tracing: light samples only (nothing
                //    else finds emitters from x, so no MIS weight: bsdf_frac 0).
                int cls_d = via_specular ? kSpecular : kDirect;
                if (mask[cls_d] && direct_samples_ > 0 && !scene.emitters.empty()) {
                    Color ld(0.f);
                    for (int i = 0; i < direct_samples_; ++i)
                        ld += estimate_direct(scene, it, bsdf, wi, sampler, stats, 1.f, 0.f);
                    out.add(cls_d, beta * ld / float(direct_samples_));
                }
                // 3. Caustics from the caustic map.
                int cls_c = via_specular ? kSpecular : kCaustic;
                if (maps.has_caustic && mask[cls_c])
                    out.add(cls_c, beta * estimate(maps.caustic, maps.r2_caustic, it, bsdf, wi,
                                                   photon_budget(max_depth_, c), nb));
                // 4. Indirect light from the global map: final gathering, or the
                //    map read at x itself.
                int cls_i = via_specular ? kSpecular : kIndirect;
                if (maps.has_global && mask[cls_i]) {
                    Color li = final_gather_ ? gather(scene, maps, sampler, it, bsdf, wi, c, nb, stats)
                                             : estimate(maps.global, maps.r2_global, it, bsdf, wi,
                                                        photon_budget(max_depth_, c), nb);
                    out.add(cls_i, beta * li);
                }
            }

            // 5. Specular reflection by Monte Carlo ray tracing: follow a delta
            //    lobe; a sampled smooth lobe ends the path (its light came from
            //    steps 2-4, and the lobe-selection weight keeps this unbiased).
            if (!(bsdf.flags() & kDelta)) break;
            if (!mask[kSpecular] && !(bsdf.flags() == kNull && !via_specular)) break;
            BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight) || !bs.is_delta) break;
            beta *= bs.weight;
            if (bsdf.flags() != kNull) pc.push(true);
            ray = it.spawn(it.to_world(bs.wo));
            float rr_u = sampler.next_1d();
            if (depth + 1 >= rr_depth_) {
                float q = std::min(max_component(beta), 0.95f);
                if (!(rr_u < q)) break;
                beta /= q;
            }
        }
    }

private:
    // Jensen 2001, eq. 7.6, over the lookup_size nearest photons within r2_max.
    Color estimate(const PhotonMap& map, float r2_max, const Interaction& it, const Bsdf& bsdf, const Vec3& wi,
                   int max_photon_depth, std::vector<Neighbour>& nb) const {
        if (max_photon_depth < 1) return Color(0.f);
        map.knn(it.p, lookup_size_, r2_max, nb, max_photon_depth);
        if (nb.empty()) return Color(0.f);
        float r2 = int(nb.size()) == lookup_size_ ? nb.back().d2 : r2_max;
        if (!(r2 > 0.f)) r2 = r2_max;  // n photons on one point: fall back to the maximum disc
        BsdfContext ctx;
        Color sum(0.f);
        for (const Neighbour& n : nb) {
            const Photon& ph = map.photons()[n.idx];
            Vec3 wp = it.to_local(ph.wi);
            float c = std::fabs(wp.z);
            if (!(c > 1e-7f)) continue;
            // eval returns f |cos theta_p|; the photon's flux already holds the cosine.
            sum += bsdf.eval(ctx, wi, wp) * ph.power * (1.f / c);
        }
        return sum * (1.f / (kPi * r2));
    }

    // Final gathering (Jensen 2001, sec. 9.3.2): gather_rays BSDF samples of
    // x's smooth lobes; each follows specular vertices to its first
    // non-specular vertex x' and reads the global map there. Emitters and
    // the environment found this way are skipped: that light is direct
    // (step 2) or caustic (step 3) at x.
    Color gather(const Scene& scene, const Maps& maps, Sampler& sampler, const Interaction& x, const Bsdf& bsdf,
                 const Vec3& wi, int c, std::vector<Neighbour>& nb, ThreadStats& stats) const {
        BsdfContext ctx;
        Color sum(0.f);
        for (int i = 0; i < gather_rays_; ++i) {
            BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight) || bs.is_delta) continue;
            Color w = bs.weight;
            Ray r = x.spawn(x.to_world(bs.wo));
            for (int g = 1; g <= 64; ++g) {  // g: segments from x to x'
                Interaction it;
                ++stats.rays;
                if (!scene.intersect(r, it)) break;
                int budget = photon_budget(max_depth_, c + g);
                if (budget < 1) break;
                const Bsdf& b2 = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
                Vec3 wi2 = it.to_local(it.wi);
                if (b2.has_smooth()) sum += w * estimate(maps.global, maps.r2_global, it, b2, wi2, budget, nb);
                if (!(b2.flags() & kDelta)) break;
                BsdfSample bs2 = b2.sample(ctx, wi2, sampler.next_1d(), sampler.next_2d());
                if (!(bs2.pdf_w > 0.f) || is_black(bs2.weight) || !bs2.is_delta) break;
                w *= bs2.weight;
                r = it.spawn(it.to_world(bs2.wo));
            }
        }
        return sum / float(gather_rays_);
    }

    int max_depth_, rr_depth_;
    bool hide_;
    int direct_samples_, global_photons_, caustic_photons_;
    float global_radius_, caustic_radius_;
    int lookup_size_, gather_rays_;
    bool final_gather_;
};

namespace {

// The camera passes of photonmapper, through the ordinary tile driver.
class PhotonMapperPass final : public Integrator {
public:
    PhotonMapperPass(const PhotonMapper& pm, const Maps& maps) : pm_(pm), maps_(maps) {}
    void sample(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out,
                ThreadStats& stats) const override {
        pm_.radiance(scene, maps_, sampler, ray, out, stats);
    }

private:
    const PhotonMapper& pm_;
    const Maps& maps_;
};

}  // namespace

RenderOutput empty_render_output(const Scene& scene, int threads, double seconds) {
    RenderOutput out;
    out.width = scene.sensor->width;
    out.height = scene.sensor->height;
    size_t n = size_t(out.width) * size_t(out.height) * 3;
    out.image.assign(n, 0.f);
    out.variance.assign(n, std::numeric_limits<float>::quiet_NaN());
    out.effects.assign(kNumEffects, std::vector<float>(n, 0.f));
    out.cancelled = true;
    out.threads = threads;
    out.seconds = seconds;
    return out;
}

RenderOutput PhotonMapper::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    auto t0 = Clock::now();
    int threads = render_threads(opts);
    const SceneFeatures& f = scene.features;
    bool lights = !scene.emitters.empty();
    bool long_paths = max_depth_ < 0 || max_depth_ >= 3;  // L S D E and L D D E have 3 segments
    bool specular_chain = f.has_delta_bsdf && mask[kSpecular];
    bool need_caustic = lights && long_paths && caustic_photons_ > 0 && f.has_smooth_bsdf && f.has_delta_bsdf &&
                        (mask[kCaustic] || specular_chain);
    bool need_global = lights && long_paths && global_photons_ > 0 && f.has_smooth_bsdf &&
                       (mask[kIndirect] || specular_chain);
    Vec3 center;
    float radius;
    scene.bounding_sphere(center, radius);
    Maps maps;
    std::vector<PhotonMapStats> info;
    ThreadStats pstats;
    uint64_t total = opts.seconds > 0 ? 0 : uint64_t(scene.sensor->width) * scene.sensor->height * uint64_t(opts.spp);
    std::function<bool()> poll_once = [&] { return !poll || poll(0, total); };
    auto build = [&](const char* name, const PhotonTraceSpec& spec, uint64_t target, PhotonMap& map) {
        PhotonPass pass = trace_photons_until(scene, spec, opts.seed, target, threads, poll_once, pstats);
        if (pass.cancelled) return false;
        PhotonMapStats s;
        s.name = name;
        s.photons = pass.photons.size();
        s.paths = pass.paths;
        s.trace_seconds = pass.seconds;
        s.target_reached = pass.target_reached;
        auto tb = Clock::now();
        map.build(std::move(pass.photons), threads);
        s.build_seconds = since(tb);
        s.bytes_per_photon = double(PhotonMap::bytes_per_photon());
        info.push_back(s);
        return true;
    };
    // Light-path segments a photon may need: at least one camera segment
    // follows it (two with final gathering, for the global map).
    if (need_caustic) {
        PhotonTraceSpec spec;
        spec.max_depth = max_depth_ < 0 ? -1 : max_depth_ - 1;
        spec.rr_depth = rr_depth_;
        spec.caustic_only = true;
        spec.stream = 1;
        if (!build("caustic", spec, uint64_t(caustic_photons_), maps.caustic))
            return empty_render_output(scene, threads, since(t0));
        maps.has_caustic = true;
        maps.r2_caustic = sqr(caustic_radius_ * radius);
    }
    if (need_global) {
        PhotonTraceSpec spec;
        spec.max_depth = max_depth_ < 0 ? -1 : max_depth_ - (final_gather_ ? 2 : 1);
        spec.rr_depth = rr_depth_;
        spec.indirect_only = !final_gather_;
        spec.stream = 2;
        if (!build("global", spec, uint64_t(global_photons_), maps.global))
            return empty_render_output(scene, threads, since(t0));
        maps.has_global = true;
        maps.r2_global = sqr(global_radius_ * radius);
    }
    // The camera passes; a time budget counts the photon passes too.
    RenderOptions o = opts;
    if (o.seconds > 0) o.seconds = std::max(opts.seconds - since(t0), 1e-3);
    PhotonMapperPass pass(*this, maps);
    pass.mask = mask;
    double photon_seconds = since(t0);
    RenderOutput out = render(scene, pass, o, poll);
    // Error-vs-time curves must count the photon passes.
    for (Checkpoint& cp : out.checkpoints) cp.seconds += photon_seconds;
    out.stats.merge(pstats);
    out.photon_maps = info;
    out.seconds = since(t0);
    return out;
}

std::unique_ptr<Integrator> make_photonmapper_integrator(const IntegratorDesc& d) {
    return std::make_unique<PhotonMapper>(d);
}

}  // namespace rm
