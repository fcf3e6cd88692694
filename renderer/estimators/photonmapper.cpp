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
// Parameters: the registration below (Mitsuba 0.6's photonmapper names in
// snake_case, its camelCase ones as aliases; radii relative to the radius of
// the scene's bounding sphere, as Mitsuba's are relative to the scene size).
// In a scene with media, max_depth counts scattering vertices (surface or
// medium; index-matched boundaries excluded), as volpath's does.
// max_depth bounds whole paths: a photon of depth d (segments from its
// emitter, photon_trace.h) is read at a vertex c segments from the camera
// only when d + c <= max_depth.
//
// Only what the scene calls for (DESIGN section 3): no caustic map unless
// the scene has both specular and non-specular surfaces and the caustic or
// specular class is simulated; no global map unless the indirect class (or
// the specular class, through specular surfaces) is; no volume map unless
// the scene has media that scatter and the volume or subsurface class is
// simulated.
// res.stats["photon_maps"] lists the maps built.
//
// Radius bias (res.error_budget's discretisation term), estimated in the
// same render: each surface radiance estimate also returns an estimate of
// its own bias, weighted into the camera sample like the estimate itself.
// With r the disc's radius and the n photons found, the estimate is
// L_in + L_rim, L_rim the n-th photon's share when the n nearest filled the
// disc (it sits on the rim: the n / (n - 1) overestimate below), else 0.
// The disc average of a radiance smooth at x is biased by c r^2 + O(r^4),
// so with L_h the inner photons within r / sqrt(2) over pi r^2 / 2,
// 2 (L_in - L_h) estimates the blur c r^2 (Richardson extrapolation in r^2),
// and the bias estimate is 2 (L_in - L_h) + L_rim. Tallied per camera
// sample into estimator stats radius_bias_sum / radius_bias_sq_sum (per
// channel) and radius_bias_samples; scenes with media are not tallied.
// The camera samples share one photon map, so the spread over them misses
// the map's own randomness (the bench's seeds see it). Wrong where the
// radiance is not smooth within r (an edge, a corner: of order r).
// Bias: the estimate blurs the photon density over the disc of radius r (and
// counts photons of nearby surfaces: corners read brighter), and n / (pi r_n^2)
// itself overestimates a Poisson density by n / (n - 1) (the n-th photon
// sits on the disc's rim); it vanishes as the photon count grows with
// n -> inf, n / N -> 0 (Jensen 2001, sec. 7.2). Measured per scene and effect
// in benchmarks/studies/photon_bias.py; sppm is the consistent form.
#include <chrono>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "core/warp.h"
#include "render/memory.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/common.h"
#include "transport/media_common.h"
#include "transport/photon_trace.h"

namespace rm {

namespace {

std::unique_ptr<Integrator> make_photonmapper(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "photonmapper";
    e.doc = "two-pass photon mapping: caustic, global and volume photon maps, final gathering (Jensen 1996, 2001)";
    e.params = {
        max_depth_param().alias("maxDepth"),
        rr_depth_param().alias("rrDepth"),
        hide_emitters_param().alias("hideEmitters"),
        ParamSpec::integer("direct_samples", 16, "shadow rays per camera sample at the first non-specular vertex")
            .at_least(0)
            .alias("directSamples"),
        ParamSpec::integer("global_photons", 250000, "photons stored in the global map")
            .at_least(0)
            .alias("globalPhotons"),
        ParamSpec::integer("caustic_photons", 250000, "photons stored in the caustic map")
            .at_least(0)
            .alias("causticPhotons"),
        ParamSpec::real("global_lookup_radius", 0.05,
                        "maximum lookup radius in the global map, relative to the scene's")
            .greater_than(0)
            .alias("globalLookupRadius"),
        ParamSpec::real("caustic_lookup_radius", 0.0125,
                        "maximum lookup radius in the caustic map, relative to the scene's")
            .greater_than(0)
            .alias("causticLookupRadius"),
        ParamSpec::integer("lookup_size", 120, "photons per radiance estimate, n").at_least(1).alias("lookupSize"),
        ParamSpec::integer("gather_rays", 32, "final-gathering rays per camera sample").at_least(1),
        ParamSpec::boolean("final_gather", true,
                           "false: the global map read at the first vertex itself (shows its bias)"),
        ParamSpec::integer("volume_photons", 250000, "photons stored in the volume map (scenes with media)")
            .at_least(0)
            .alias("volumePhotons"),
        ParamSpec::real("volume_lookup_radius", 0.05,
                        "maximum lookup radius in the volume map, relative to the scene's")
            .greater_than(0)
            .alias("volumeLookupRadius"),
        ParamSpec::integer("volume_lookup_size", 64, "photons per volume radiance estimate").at_least(1),
        ParamSpec::real("step_size", 0.0,
                        "ray-marching step in world units (automatic: one mean free path of the medium's densest "
                        "channel, at most 1/16 of the scene's radius)")
            .at_least(0)
            .with_special(0.0, "automatic"),
        ParamSpec::integer("volume_boundary_rays", 0,
                           "K > 0: correct the volume estimate's sphere for its part outside the medium with K rays")
            .at_least(0)
            .at_most(1024)
            .with_special(int64_t(0), "the seed's 4/3 pi r^3"),
        ParamSpec::mitsuba_ignored("granularity", "Mitsuba's work-unit size: changes nothing here"),
    };
    e.caps.media = true;
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Biased;
    e.factory = make_photonmapper;
    return e;
}());

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct Maps {
    PhotonMap caustic, global;
    bool has_caustic = false, has_global = false;
    float r2_caustic = 0.f, r2_global = 0.f;
    // Scenes with media: the volume photon map, one kd-tree per medium (a
    // lookup must not count photons of a neighbouring medium), and the
    // ray-marching step of each medium.
    std::vector<PhotonMap> volume;
    bool has_volume = false;
    float r2_volume = 0.f;
    std::vector<float> step;
    Vec3 center;
    float radius = 1.f;
};

// Ray marching gives up on a segment's quadrature beyond this many steps
// (the step grows to fit: a too-small step_size costs time, not a hang).
constexpr int kMaxMarchSteps = 1 << 16;
// Russian roulette on the transmittance along a marched ray once it falls
// below this (survivors are divided by their probability: unbiased).
constexpr float kMarchRR = 1e-2f;

// Photons of depth d may be read c segments from the camera when d + c <= max_depth.
inline int photon_budget(int max_depth, int camera_segments) {
    return max_depth < 0 ? 255 : std::min(255, max_depth - camera_segments);
}

}  // namespace

class PhotonMapper final : public Integrator {
public:
    explicit PhotonMapper(ParamReader& p)
        : max_depth_(p.get_int("max_depth")),
          rr_depth_(p.get_int("rr_depth")),
          hide_(p.get_bool("hide_emitters")),
          direct_samples_(p.get_int("direct_samples")),
          global_photons_(p.get_int("global_photons")),
          caustic_photons_(p.get_int("caustic_photons")),
          global_radius_(p.get_float("global_lookup_radius")),
          caustic_radius_(p.get_float("caustic_lookup_radius")),
          lookup_size_(p.get_int("lookup_size")),
          gather_rays_(p.get_int("gather_rays")),
          final_gather_(p.get_bool("final_gather")),
          volume_photons_(p.get_int("volume_photons")),
          volume_radius_(p.get_float("volume_lookup_radius")),
          volume_lookup_size_(p.get_int("volume_lookup_size")),
          step_size_(p.get_float("step_size")),
          boundary_rays_(p.get_int("volume_boundary_rays")) {}

    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'photonmapper' renders through its own driver");
    }

    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;
    // The photon maps the scene calls for (DESIGN section 3).
    struct MapNeeds {
        bool caustic = false, global = false, volume = false;
    };
    MapNeeds needs(const Scene& scene) const;
    // The films, the output and the maps against the machine's memory (memory.h).
    void check_memory_for(const Scene& scene, const RenderOptions& opts) const;
    // Pass 1: the photon maps the scene calls for, and the ray-marching
    // steps; false when cancelled.
    bool photon_pass(PassLoop& loop, Maps& maps, std::vector<PhotonMapStats>& info, ThreadStats& pstats) const;

    // Pass 2: the radiance along one camera ray, split four ways (top of
    // file); `bias` gets its radius-bias estimate (surfaces only).
    void radiance(const Scene& scene, const Maps& maps, Sampler& sampler, const Ray& camera_ray, EffectRadiance& out,
                  ThreadStats& stats, Color& bias) const {
        if (scene.features.has_media) return radiance_media(scene, maps, sampler, camera_ray, out, stats);
        // The thread's lookup buffer, found once per camera ray through a
        // call (a thread_local named here is looked up again at every use).
        std::vector<Neighbour>& nb = tl_neighbours();
        // 1. Each vertex of the chain, with the emission it shows (reached
        //    from the camera directly or through specular vertices only).
        walk_specular_chain(
            scene, sampler, camera_ray, SpecularChain{max_depth_, rr_depth_, hide_}, mask, out, stats,
            [&](const Interaction& it, const Bsdf& bsdf, const Vec3& wi, const Color& beta, const PathClass& pc,
                int depth) {
                const int c = depth + 1;  // segments from the camera to x
                const bool via_specular = pc.scatter_vertices > 0;
                if (bsdf.has_smooth()) {
                    // 2. Direct light by ray tracing: light samples only (nothing
                    //    else finds emitters from x, so no MIS weight: bsdf_frac 0).
                    // 3. Caustics from the caustic map.
                    direct_and_caustics(scene, maps, it, bsdf, wi, c, via_specular, beta, out, nb, bias,
                                        [&] { return estimate_direct(scene, it, bsdf, wi, sampler, stats, 1.f, 0.f); });
                    // 4. Indirect light from the global map: final gathering, or the
                    //    map read at x itself.
                    int cls_i = via_specular ? kSpecular : kIndirect;
                    if (maps.has_global && mask[cls_i]) {
                        Color b(0.f);
                        Color li = final_gather_ ? gather(scene, maps, sampler, it, bsdf, wi, c, nb, stats, &b)
                                                 : estimate(maps.global, maps.r2_global, it, bsdf, wi,
                                                            photon_budget(max_depth_, c), nb, nullptr, &b);
                        out.add(cls_i, beta * li);
                        bias += beta * b;
                    }
                }
                // 5. Specular reflection by Monte Carlo ray tracing: follow a delta
                //    lobe (the chain samples it); a sampled smooth lobe ends the path
                //    (its light came from steps 2-4, and the lobe-selection weight
                //    keeps this unbiased).
                if (!(bsdf.flags() & kDelta)) return false;
                return mask[kSpecular] || (bsdf.flags() == kNull && !via_specular);
            });
    }

private:
    // At a camera vertex x with a smooth lobe, in both camera loops
    // (radiance, radiance_media): direct light as the mean of
    // direct_samples_ light samples, each from `direct_one()` (the surface
    // or the through-media estimator), and caustics from the caustic map
    // (its radius-bias estimate added to `bias`); c: segments from the
    // camera to x.
    template <typename DirectF>
    void direct_and_caustics(const Scene& scene, const Maps& maps, const Interaction& it, const Bsdf& bsdf,
                             const Vec3& wi, int c, bool via_specular, const Color& beta, EffectRadiance& out,
                             std::vector<Neighbour>& nb, Color& bias, DirectF direct_one) const {
        int cls_d = via_specular ? kSpecular : kDirect;
        if (mask[cls_d] && direct_samples_ > 0 && !scene.emitters.empty()) {
            Color ld(0.f);
            for (int i = 0; i < direct_samples_; ++i) ld += direct_one();
            out.add(cls_d, beta * ld / float(direct_samples_));
        }
        int cls_c = via_specular ? kSpecular : kCaustic;
        if (maps.has_caustic && mask[cls_c]) {
            Color b(0.f);
            out.add(cls_c, beta * estimate(maps.caustic, maps.r2_caustic, it, bsdf, wi, photon_budget(max_depth_, c),
                                           nb, nullptr, &b));
            bias += beta * b;
        }
    }

    // Jensen 2001, eq. 7.6, over the lookup_size nearest photons within r2_max.
    // by_medium (scenes with media): photons whose light path scattered in a
    // medium go to by_medium[0] (volume class) or [1] (subsurface) instead
    // of the returned sum.
    Color estimate(const PhotonMap& map, float r2_max, const Interaction& it, const Bsdf& bsdf, const Vec3& wi,
                   int max_photon_depth, std::vector<Neighbour>& nb, Color* by_medium = nullptr,
                   Color* bias = nullptr) const {
        if (max_photon_depth < 1) return Color(0.f);
        map.knn(it.p, lookup_size_, r2_max, nb, max_photon_depth);
        if (nb.empty()) return Color(0.f);
        const bool full = int(nb.size()) == lookup_size_;
        float r2 = full ? nb.back().d2 : r2_max;
        if (!(r2 > 0.f)) r2 = r2_max;  // n photons on one point: fall back to the maximum disc
        BsdfContext ctx;
        ctx.set(it);
        Color sum(0.f), half(0.f), rim(0.f);
        const Neighbour* const found = nb.data();
        const size_t m = nb.size();
        const size_t last = full ? m - 1 : m;  // the rim photon of a full lookup (none otherwise)
        const Photon* const photons = map.photons().data();
        for (size_t k = 0; k < m; ++k) {
            const Neighbour& n = found[k];
            const Photon& ph = photons[n.idx];
            Vec3 wp = it.to_local(ph.wi);
            float c = std::fabs(wp.z);
            if (!(c > 1e-7f)) continue;
            // eval returns f |cos theta_p|; the photon's flux already holds the cosine.
            Color v = bsdf.eval(ctx, wi, wp) * ph.power * (1.f / c);
            if (by_medium && (ph.flags & kPhotonVolumePath))
                by_medium[0] += v * (1.f / (kPi * r2));
            else if (by_medium && (ph.flags & kPhotonSubsurfacePath))
                by_medium[1] += v * (1.f / (kPi * r2));
            else {
                sum += v;
                if (k == last)
                    rim += v;
                else if (2.f * n.d2 <= r2)
                    half += v;
            }
        }
        if (bias) *bias = (2.f * (sum - rim) - 4.f * half + rim) * (1.f / (kPi * r2));
        return sum * (1.f / (kPi * r2));
    }

    // Final gathering (Jensen 2001, sec. 9.3.2): gather_rays BSDF samples of
    // x's smooth lobes; each follows specular vertices to its first
    // non-specular vertex x' and reads the global map there. Emitters and
    // the environment found this way are skipped: that light is direct
    // (step 2) or caustic (step 3) at x.
    Color gather(const Scene& scene, const Maps& maps, Sampler& sampler, const Interaction& x, const Bsdf& bsdf,
                 const Vec3& wi, int c, std::vector<Neighbour>& nb, ThreadStats& stats, Color* bias = nullptr) const {
        BsdfContext ctx;
        Color sum(0.f), bsum(0.f);
        for (int i = 0; i < gather_rays_; ++i) {
            ctx.set(x);
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
                if (b2.has_smooth()) {
                    Color b(0.f);
                    sum += w * estimate(maps.global, maps.r2_global, it, b2, wi2, budget, nb, nullptr, &b);
                    bsum += w * b;
                }
                if (!(b2.flags() & kDelta)) break;
                ctx.set(it);
                BsdfSample bs2 = b2.sample(ctx, wi2, sampler.next_1d(), sampler.next_2d());
                if (!(bs2.pdf_w > 0.f) || is_black(bs2.weight) || !bs2.is_delta) break;
                w *= bs2.weight;
                r = it.spawn(it.to_world(bs2.wo));
            }
        }
        if (bias) *bias = bsum / float(gather_rays_);
        return sum / float(gather_rays_);
    }

    // Scenes with media (photonmapper_media.inc): the camera loop, ray
    // marching, the volume radiance estimate, light sampling through media
    // and final gathering through media.
    void radiance_media(const Scene& scene, const Maps& maps, Sampler& sampler, const Ray& camera_ray,
                        EffectRadiance& out, ThreadStats& stats) const;
    Color march(const Scene& scene, const Maps& maps, Sampler& sampler, const Ray& ray, float t_hit,
                const MediumTracker& mt, const PathClass& pc, int c, const Color& beta, EffectRadiance& out,
                std::vector<Neighbour>& nb, ThreadStats& stats) const;
    Color volume_estimate(const Scene& scene, const Maps& maps, int medium, const Vec3& p, const Vec3& wi,
                          const PhaseFunction& phase, int max_photon_depth, std::vector<Neighbour>& nb,
                          Sampler& sampler, ThreadStats& stats) const;
    Color gather_media(const Scene& scene, const Maps& maps, Sampler& sampler, const Interaction& x, const Bsdf& bsdf,
                       const Vec3& wi, int c, const MediumTracker& mt, const PathClass& pc, const Color& beta,
                       EffectRadiance& out, std::vector<Neighbour>& nb, ThreadStats& stats) const;

    // The thread's photon lookup buffer.
    [[gnu::noinline]] static std::vector<Neighbour>& tl_neighbours() {
        thread_local std::vector<Neighbour> nb;
        return nb;
    }

    int max_depth_, rr_depth_;
    bool hide_;
    int direct_samples_, global_photons_, caustic_photons_;
    float global_radius_, caustic_radius_;
    int lookup_size_, gather_rays_;
    bool final_gather_;
    int volume_photons_;
    float volume_radius_;
    int volume_lookup_size_;
    float step_size_;
    int boundary_rays_;
};

// ---------------------------------------------------------------------------
// Scenes with media: the volume photon map and ray marching (Jensen &
// Christensen 1998, "Efficient simulation of light transport in scenes with
// participating media using photon maps"; Jensen 2001, ch. 10; the seed's
// "photon tracing - participating media" and "- subsurface scattering").
//
// Pass 1 (photon_trace.cpp) walks photons through the media: free flights of
// mean 1 / sigma_t, scatter with probability sigma_s / sigma_t else absorb,
// new directions from the phase function, refraction at dielectric
// boundaries, none at index-matched ones. A volume photon is stored at each
// medium scattering event that follows another scattering vertex (L X+ V:
// multiple scattering, volume caustics, light refracted into a translucent
// object). Single scattering (L V: light reaching the medium point straight
// from an emitter, through media and null boundaries) is not stored: the
// camera pass computes it by light sampling, as Jensen & Christensen
// compute single scattering by ray marching with shadow rays and keep the
// volume map for the indirect (multiply scattered) part.
// The two cover disjoint path sets, so nothing is counted twice. Light
// entering a translucent object through its dielectric surface is a
// specular vertex (shadow rays cannot pass glass), so inside such an object
// all in-scattered light comes from the photon map.
//
// Pass 2 marches along every camera ray segment through a medium (the
// seed's "ray marching (numerical solution of differential equation)";
// Jensen & Christensen 1998's ray marching, Jensen 2001, ch. 10,
// here with a fixed, jittered step; equation numbers of those texts are
// not cited here because they could not be checked):
//   L(x, w) = sum_k Tr(x, x_k) [sigma_s(x_k) L_d(x_k, w) + L_m(x_k, w)] dt
//             + Tr(x, x_s) L(x_s, w),
// x_k = x + (k + u) dt w, one uniform jitter u per segment and camera
// sample (so the sum's expectation is the integral over the segment
// exactly; only the photon estimate is biased), Tr by Beer-Lambert (ratio
// tracking, unbiased, in grid media), x_s the surface that ends the segment.
//   L_d = int p(w', w) L_direct(x_k, w') dw', one light sample through
//         media (Scene::transmittance);
//   L_m = sigma_s int p L_indirect dw' ~ sum_p p(w_p, w) Phi_p / (4/3 pi r^3)
//         over the volume_lookup_size nearest volume photons (the seed's
//         formula; Jensen & Christensen 1998's volume radiance estimate).
//         Units: the seed's L(x, w') = d^2 Phi / (sigma_s dw' dV), i.e. the
//         photons scattered per unit volume and solid angle are
//         d^2 Phi = sigma_s L dw dV, so the sum over the sphere's volume
//         already carries sigma_s: no sigma_s factor on L_m, unlike L_d
//         (W / (m^3 sr), integrated over dt [m] to radiance).
// Both estimates read only what the camera path may still use (max_depth).
// Surfaces along the way are lit as without media (direct light through
// media, caustic map, final gathering), times the transmittance of the
// segment. Final-gathering rays in a medium take one free flight (volpath's
// sampler) and at a scattering point y read sigma_s [L_d(y) + L_m(y) /
// sigma_s(y)] weighted by the flight's spectral-MIS weight: an unbiased
// one-sample version of the marching above, since a full march per gather
// ray would cost gather_rays times a camera ray's march.
//
// Bias of the volume estimate: the sphere of radius r blurs the in-scattered
// radiance, n / r_n^3 over-estimates a Poisson density by n / (n - 1), and a
// sphere that pokes out of the medium holds photons in only part of its
// volume, so the estimate is low near a boundary (up to half at a flat one);
// volume_boundary_rays > 0 measures the sphere's part inside the medium
// instead (volume_estimate). Figures: docs/measurements.md.
// ---------------------------------------------------------------------------

namespace {

Interaction medium_vertex(const Vec3& p, const Vec3& wi) {
    Interaction mi;
    mi.kind = VertexKind::Medium;
    mi.valid = true;
    mi.p = p;
    mi.wi = wi;
    return mi;
}

Color sigma_s_at(const Medium& med, const Vec3& p) {
    if (med.homogeneous) return med.sigma_s;
    Color st, ss;
    med.coefficients(p, st, ss);
    return ss;
}

// Distance along `ray` (origin inside or outside) to where it leaves the
// sphere (center, radius); 0 when it never is inside it.
float sphere_exit(const Ray& ray, const Vec3& center, float radius) {
    Vec3 oc = ray.o - center;
    float b = dot(oc, ray.d), c = dot(oc, oc) - radius * radius;
    float disc = b * b - c;
    if (!(disc > 0.f)) return 0.f;
    return std::max(0.f, -b + std::sqrt(disc));
}

}  // namespace

// The volume radiance estimate L_m (above; the seed's Phi / (4/3 pi r^3)):
// sum over the n nearest photons of medium `medium` within the maximum
// radius of p(w_p, w) Phi_p, over the sphere's volume (r: the n-th photon's
// distance, or the maximum radius when fewer are found).
//
// volume_boundary_rays K > 0 (ours; off by default, the seed's estimate):
// near a boundary the sphere holds photons only in its part inside the
// medium, so 4/3 pi r^3 overstates the volume they came from (the boundary
// bias above). The part inside, seen from p, is V = int_S2 min(d(w), r)^3 / 3
// dw, d(w) the distance to the first surface in direction w; K rays,
// stratified in cos theta with a random azimuth, estimate it as
// (4 pi / K) sum_k min(d_k, r)^3 / 3 (exact in expectation for whatever is
// visible from p; surfaces inside the sphere with photons behind them make
// it overcorrect). The ratio to the estimate is consistent, not unbiased.
Color PhotonMapper::volume_estimate(const Scene& scene, const Maps& maps, int medium, const Vec3& p, const Vec3& wi,
                                    const PhaseFunction& phase, int max_photon_depth, std::vector<Neighbour>& nb,
                                    Sampler& sampler, ThreadStats& stats) const {
    if (!maps.has_volume || max_photon_depth < 1 || medium < 0 || medium >= int(maps.volume.size())) return Color(0.f);
    const PhotonMap& map = maps.volume[medium];
    if (map.empty()) return Color(0.f);
    map.knn(p, volume_lookup_size_, maps.r2_volume, nb, max_photon_depth);
    if (nb.empty()) return Color(0.f);
    float r2 = int(nb.size()) == volume_lookup_size_ ? nb.back().d2 : maps.r2_volume;
    if (!(r2 > 0.f)) r2 = maps.r2_volume;
    Color sum(0.f);
    for (const Neighbour& n : nb) {
        const Photon& ph = map.photons()[n.idx];
        sum += ph.power * phase.eval(wi, ph.wi);
    }
    float volume_fraction = 1.f;
    if (boundary_rays_ > 0) {
        float r = std::sqrt(r2), frac = 0.f;
        Vec2 u = sampler.next_2d();
        for (int k = 0; k < boundary_rays_; ++k) {
            // Stratified in z (= cos theta), azimuth by the golden angle from u.y.
            float uz = (float(k) + u.x) / float(boundary_rays_);
            float uphi = u.y + float(k) * 0.6180339887f;
            Vec3 d = warp::square_to_uniform_sphere(Vec2(uz, uphi - std::floor(uphi)));
            Interaction it;
            ++stats.rays;
            float t = scene.intersect(Ray{p, d, 0.f, r}, it) ? std::min(it.t, r) : r;
            frac += (t / r) * (t / r) * (t / r);
        }
        // Floored at 1/K, so that a lookup boxed in by nearby surfaces cannot blow up.
        volume_fraction = std::max(frac / float(boundary_rays_), 1.f / float(boundary_rays_));
    }
    return sum * (1.f / ((4.f / 3.f) * kPi * r2 * std::sqrt(r2) * volume_fraction));
}

// Ray marching over the segment [0, t_hit) of `ray` through the current
// medium (top of this part): adds the in-scattered radiance, times `beta`,
// to `out` and returns the segment's transmittance (with the Russian
// roulette weight; zero when the roulette ended the ray).
Color PhotonMapper::march(const Scene& scene, const Maps& maps, Sampler& sampler, const Ray& ray, float t_hit,
                          const MediumTracker& mt, const PathClass& pc, int c, const Color& beta, EffectRadiance& out,
                          std::vector<Neighbour>& nb, ThreadStats& stats) const {
    const int m = mt.medium;
    const Medium& med = *scene.media[m];
    // A ray that leaves the scene in an unbounded homogeneous medium is
    // marched to 20 mean free paths of its thinnest channel (transmittance
    // e^-20), but at least to the scene's bounding sphere and at most 64
    // times its radius (about 1000 automatic steps); beyond, only the
    // transmittance to infinity (0, or 1 in a channel without extinction)
    // is kept: in-scattering that far out is left out (a truncation).
    Color beyond(1.f);
    float t_max = t_hit;
    if (std::isinf(t_hit) && med.homogeneous) {
        float far = 64.f * maps.radius;
        float st_min = min_component(med.sigma_t);
        if (st_min > 0.f) far = std::min(far, 20.f / st_min);
        t_max = std::max(sphere_exit(ray, maps.center, maps.radius * 1.01f), far);
        beyond = med.transmittance(kInf);
    }
    float t0, t1;  // where the medium is (a grid's box; everywhere for the others)
    if (!med.extent(ray.o, ray.d, t_max, t0, t1) || !(t1 > t0)) return beyond;
    // In-scattering at x_k: a medium vertex one segment after the camera
    // path's c - 1 vertices, filed as V or B (PathClass).
    PathClass pn = pc;
    pn.push_medium(mt.enclosed);
    const int cls = pn.classify();
    const bool nee = mask[cls] && !scene.emitters.empty() && (max_depth_ < 0 || c + 1 <= max_depth_);
    const int budget = mask[cls] ? photon_budget(max_depth_, c) : 0;
    if (!nee && budget < 1) return med.segment_transmittance(ray.o + ray.d * t0, ray.d, t1 - t0, sampler) * beyond;
    float dt = maps.step[m];
    if ((t1 - t0) / dt > float(kMaxMarchSteps)) dt = (t1 - t0) / float(kMaxMarchSteps);
    const float u = sampler.next_1d();
    const PhaseFunction& phase = *med.phase;
    const Vec3 wi = -ray.d;
    Color tr(1.f);
    float t_prev = t0;
    for (int k = 0; k <= kMaxMarchSteps; ++k) {
        float t = t0 + (float(k) + u) * dt;
        if (!(t < t1)) break;
        tr *= med.segment_transmittance(ray.o + ray.d * t_prev, ray.d, t - t_prev, sampler);
        t_prev = t;
        float tm = max_component(tr);
        if (tm < kMarchRR) {
            if (!(sampler.next_1d() * kMarchRR < tm)) return Color(0.f);
            tr /= tm / kMarchRR;
        }
        Vec3 y = ray.o + ray.d * t;
        Color ss = sigma_s_at(med, y);
        if (is_black(ss)) continue;
        Interaction mi = medium_vertex(y, wi);
        Color s(0.f);
        if (nee)
            s += ss *
                 direct_through_media(
                     scene, mi, m, sampler, stats, [&](const Vec3& wo) { return Color(phase.eval(wi, wo)); }, nullptr);
        s += volume_estimate(scene, maps, m, y, wi, phase, budget, nb, sampler, stats);
        out.add(cls, beta * tr * s * dt);
    }
    tr *= med.segment_transmittance(ray.o + ray.d * t_prev, ray.d, t1 - t_prev, sampler);
    return tr * beyond;
}

// Final gathering from x in a scene with media (see gather() and the top of
// this part): returns the surface part (global map at x', times the
// transmittance), and adds what the gather rays' medium points in-scatter
// to `out` under their own class (V or B), times `beta`.
Color PhotonMapper::gather_media(const Scene& scene, const Maps& maps, Sampler& sampler, const Interaction& x,
                                 const Bsdf& bsdf, const Vec3& wi, int c, const MediumTracker& mt, const PathClass& pc,
                                 const Color& beta, EffectRadiance& out, std::vector<Neighbour>& nb,
                                 ThreadStats& stats) const {
    BsdfContext ctx;
    Color sum(0.f);
    const float inv_n = 1.f / float(gather_rays_);
    for (int i = 0; i < gather_rays_; ++i) {
        ctx.set(x);
        BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
        float u_hero = sampler.next_1d();
        if (!(bs.pdf_w > 0.f) || is_black(bs.weight) || bs.is_delta) continue;
        SpectralThroughput th(std::min(int(u_hero * 3.f), 2), bs.weight);
        Vec3 wo = x.to_world(bs.wo);
        MediumTracker gm = mt;
        gm.cross(x, wo, false);
        Ray r = x.spawn(wo);
        PathClass pg = pc;
        pg.push(false);                                                 // x
        for (int g = 1, guard = 0; g <= 64 && guard < 1024; ++guard) {  // g: segments from x (null boundaries excluded)
            Interaction it;
            ++stats.rays;
            bool hit = scene.intersect(r, it);
            if (gm.medium >= 0) {
                const Medium& med = *scene.media[gm.medium];
                float t = 0.f;
                FlightEvent ev = free_flight(med, r, hit ? it.t : r.tmax, sampler, th, t);
                if (ev == kAbsorbed) break;
                if (ev == kScattered) {
                    // th.beta = (BSDF weight) Tr sigma_s / p(t): times
                    // int p L dw' = L_d + L_m / sigma_s at y.
                    PathClass py = pg;
                    py.push_medium(gm.enclosed);
                    int cls = py.classify();
                    if (!mask[cls]) break;
                    Vec3 y = r.o + r.d * t;
                    Interaction mi = medium_vertex(y, -r.d);
                    const PhaseFunction& phase = *med.phase;
                    Color li(0.f);
                    if (!scene.emitters.empty() && (max_depth_ < 0 || c + g + 1 <= max_depth_))
                        li += direct_through_media(
                            scene, mi, gm.medium, sampler, stats,
                            [&](const Vec3& w2) { return Color(phase.eval(mi.wi, w2)); }, nullptr);
                    Color lm = volume_estimate(scene, maps, gm.medium, y, mi.wi, phase,
                                               photon_budget(max_depth_, c + g), nb, sampler, stats);
                    Color ss = sigma_s_at(med, y);
                    for (int ch = 0; ch < 3; ++ch)
                        if (ss[ch] > 0.f) li[ch] += lm[ch] / ss[ch];
                    out.add(cls, beta * th.beta * li * inv_n);
                    break;
                }
            }
            if (!hit) break;
            const Bsdf& b2 = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
            if (b2.flags() == kNull) {
                gm.cross(it, r.d, true);
                r = it.spawn(r.d);
                continue;
            }
            int budget = photon_budget(max_depth_, c + g);
            if (budget < 1) break;
            Vec3 wi2 = it.to_local(it.wi);
            if (b2.has_smooth() && maps.has_global) {
                Color split[2] = {Color(0.f), Color(0.f)};
                sum += th.beta * estimate(maps.global, maps.r2_global, it, b2, wi2, budget, nb, split);
                if (mask[kVolume]) out.add(kVolume, beta * th.beta * split[0] * inv_n);
                if (mask[kSubsurface]) out.add(kSubsurface, beta * th.beta * split[1] * inv_n);
            }
            if (!(b2.flags() & kDelta)) break;
            ctx.set(it);
            BsdfSample bs2 = b2.sample(ctx, wi2, sampler.next_1d(), sampler.next_2d());
            if (!(bs2.pdf_w > 0.f) || is_black(bs2.weight) || !bs2.is_delta) break;
            th.beta *= bs2.weight;
            pg.push(true);
            Vec3 wo2 = it.to_world(bs2.wo);
            gm.cross(it, wo2, false);
            r = it.spawn(wo2);
            ++g;
        }
    }
    return sum * inv_n;
}

// Pass 2 in a scene with media: the surface loop of radiance() with the
// camera path tracking its medium (MediumTracker), crossing index-matched
// boundaries without a vertex, and marching every segment through a medium.
void PhotonMapper::radiance_media(const Scene& scene, const Maps& maps, Sampler& sampler, const Ray& camera_ray,
                                  EffectRadiance& out, ThreadStats& stats) const {
    thread_local std::vector<Neighbour> nb;
    // From the near-clip point, as volpath (the medium starts there).
    Ray ray = camera_ray;
    ray.o = ray.o + ray.d * ray.tmin;
    ray.tmax = std::isinf(ray.tmax) ? kInf : ray.tmax - ray.tmin;
    ray.tmin = 0.f;
    MediumTracker mt{scene.sensor_desc.medium, false};
    Color beta(1.f);
    PathClass pc;
    BsdfContext ctx;
    int cv = 0;  // scattering vertices of the camera path so far (null boundaries excluded)
    for (int guard = 0; guard < (1 << 16); ++guard) {
        // 1. The next surface, and the medium before it, marched.
        Interaction it;
        ++stats.rays;
        bool hit = scene.intersect(ray, it);
        if (mt.medium >= 0) {
            beta *= march(scene, maps, sampler, ray, hit ? it.t : kInf, mt, pc, cv + 1, beta, out, nb, stats);
            if (is_black(beta)) break;
        }
        // 2. Emission seen from the camera, through media, null boundaries
        //    and specular vertices only.
        int cls = pc.classify();
        bool count = !(cv == 0 && hide_) && mask[cls];
        if (!hit) {
            if (count)
                for (const Emitter* e : scene.environment) out.add(cls, beta * e->eval_environment(ray.d));
            break;
        }
        const Shape& shape = *scene.shapes[it.shape];
        if (shape.emitter >= 0 && count) out.add(cls, beta * scene.emitters[shape.emitter]->eval(it, it.wi));
        const Bsdf& bsdf = *scene.bsdfs[shape.bsdf];
        if (bsdf.flags() == kNull) {
            mt.cross(it, ray.d, true);
            ray = it.spawn(ray.d);
            continue;
        }
        if (max_depth_ >= 0 && cv + 1 >= max_depth_) break;
        Vec3 wi = it.to_local(it.wi);
        ctx.set(it);
        const int c = cv + 1;
        const bool via_specular = pc.scatter_vertices > 0;
        if (bsdf.has_smooth()) {
            // 3. Direct light, through media.
            // 4. Caustics from the caustic map (its photons came through
            //    media unscattered: L S+ D).
            Color untallied(0.f);  // scenes with media: no radius-bias estimate
            direct_and_caustics(scene, maps, it, bsdf, wi, c, via_specular, beta, out, nb, untallied, [&] {
                return direct_through_media(
                    scene, it, mt.medium, sampler, stats,
                    [&](const Vec3& wo) { return bsdf.eval(ctx, wi, it.to_local(wo)); }, nullptr);
            });
            // 5. Indirect light: final gathering through media, or the global
            //    map at x. Global photons whose light scattered in a medium
            //    on its way are filed as volume or subsurface light.
            int cls_i = via_specular ? kSpecular : kIndirect;
            bool any = mask[cls_i] || mask[kVolume] || mask[kSubsurface];
            if (any && final_gather_ && (maps.has_global || maps.has_volume)) {
                Color li = gather_media(scene, maps, sampler, it, bsdf, wi, c, mt, pc, beta, out, nb, stats);
                if (mask[cls_i]) out.add(cls_i, beta * li);
            } else if (any && maps.has_global) {
                Color split[2] = {Color(0.f), Color(0.f)};
                Color li = estimate(maps.global, maps.r2_global, it, bsdf, wi, photon_budget(max_depth_, c), nb, split);
                if (mask[cls_i]) out.add(cls_i, beta * li);
                if (mask[kVolume]) out.add(kVolume, beta * split[0]);
                if (mask[kSubsurface]) out.add(kSubsurface, beta * split[1]);
            }
        }
        // 6. Specular reflection and refraction by Monte Carlo ray tracing;
        //    refraction into a translucent object's medium continues the
        //    march inside it (the seed's subsurface scattering by ray marching).
        if (!(bsdf.flags() & kDelta)) break;
        BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
        if (!(bs.pdf_w > 0.f) || is_black(bs.weight) || !bs.is_delta) break;
        beta *= bs.weight;
        pc.push(true);
        ++cv;
        Vec3 wo = it.to_world(bs.wo);
        mt.cross(it, wo, false);
        ray = it.spawn(wo);
        if (!survives_roulette(RouletteRule::Capped, cv, rr_depth_, max_component(beta), sampler.next_1d(), beta))
            break;
    }
}

RenderOutput PhotonMapper::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    // 1. Pass 1, the photon maps: the loop's setup, whose time counts
    //    against a time budget (and in the checkpoints' seconds).
    check_memory_for(scene, opts);
    PassLoop loop(scene, opts, poll);
    Maps maps;
    std::vector<PhotonMapStats> info;
    ThreadStats pstats;
    if (!photon_pass(loop, maps, info, pstats)) return loop.cancelled_output();
    // 2. Pass 2, the camera passes, through the camera driver.
    //    Each camera sample's radius-bias estimate is tallied (top of file;
    //    surfaces only), under a lock: one sample's gather rays cost far more.
    const bool tally = !scene.features.has_media && (maps.has_caustic || maps.has_global);
    std::mutex tally_mutex;
    const bool shared_tally = loop.threads() > 1;  // one render thread needs no lock
    double bias_sum[3] = {0, 0, 0}, bias_sq[3] = {0, 0, 0};
    uint64_t bias_n = 0;
    CameraView pass(*this,
                    [&](const Scene& sc, Sampler& sampler, const Ray& ray, EffectRadiance& o, ThreadStats& stats) {
                        Color b(0.f);
                        radiance(sc, maps, sampler, ray, o, stats, b);
                        if (!tally) return;
                        std::unique_lock<std::mutex> lock(tally_mutex, std::defer_lock);
                        if (shared_tally) lock.lock();
                        for (int ch = 0; ch < 3; ++ch) {
                            bias_sum[ch] += double(b[ch]);
                            bias_sq[ch] += double(b[ch]) * double(b[ch]);
                        }
                        ++bias_n;
                    });
    auto tc = Clock::now();
    RenderOutput out = render_camera_paths(loop, pass);
    const double camera_seconds = since(tc);
    if (tally && bias_n > 0) {
        out.estimator_stats.push_back({"radius_bias_sum", {bias_sum[0], bias_sum[1], bias_sum[2]}});
        out.estimator_stats.push_back({"radius_bias_sq_sum", {bias_sq[0], bias_sq[1], bias_sq[2]}});
        out.estimator_stats.push_back({"radius_bias_samples", {double(bias_n)}});
    }
    // 3. The photon passes' counters and maps, and where the time went
    //    (benchmarks/studies/photon_passes.py).
    out.stats.merge(pstats);
    out.photon_maps = info;
    double trace_seconds = 0, build_seconds = 0;
    for (const PhotonMapStats& s : info) {
        trace_seconds += s.trace_seconds;
        build_seconds += s.build_seconds;
    }
    out.estimator_stats.push_back({"phase_seconds_photon_trace", {trace_seconds}});
    out.estimator_stats.push_back({"phase_seconds_photon_build", {build_seconds}});
    out.estimator_stats.push_back({"phase_seconds_camera", {camera_seconds}});
    out.seconds = loop.elapsed();
    return out;
}

PhotonMapper::MapNeeds PhotonMapper::needs(const Scene& scene) const {
    const SceneFeatures& f = scene.features;
    bool lights = !scene.emitters.empty();
    bool long_paths = max_depth_ < 0 || max_depth_ >= 3;  // L S D E and L D D E have 3 segments
    bool specular_chain = f.has_delta_bsdf && mask[kSpecular];
    MapNeeds n;
    n.caustic = lights && long_paths && caustic_photons_ > 0 && f.has_smooth_bsdf && f.has_delta_bsdf &&
                (mask[kCaustic] || specular_chain);
    n.global = lights && long_paths && global_photons_ > 0 && f.has_smooth_bsdf && (mask[kIndirect] || specular_chain);
    // Purely absorbing media (homogeneous with sigma_s = 0) never store one.
    bool scattering_media = false;
    for (const auto& med : scene.media) scattering_media |= !med->homogeneous || !is_black(med->sigma_s);
    n.volume = lights && f.has_media && scattering_media && volume_photons_ > 0 && long_paths &&
               (mask[kVolume] || mask[kSubsurface]);
    return n;
}

void PhotonMapper::check_memory_for(const Scene& scene, const RenderOptions& opts) const {
    const int W = scene.sensor->width, H = scene.sensor->height;
    const MapNeeds need = needs(scene);
    std::vector<MemoryPart> parts = {camera_film_memory(W, H), output_memory(opts, W, H)};
    // Each map's photons stay for the camera passes; the one being built
    // has its tree's copy besides (the largest is the worst case).
    const double per = double(PhotonMap::bytes_per_photon());
    double largest = 0;
    std::string largest_param;
    auto map = [&](bool needed, const char* name, const char* param, int count) {
        if (!needed) return;
        parts.push_back(
            {std::string(name) + " photon map (" + std::to_string(count) + " photons)", per * count, param});
        if (count > largest) {
            largest = count;
            largest_param = param;
        }
    };
    map(need.caustic, "caustic", "caustic_photons", caustic_photons_);
    map(need.global, "global", "global_photons", global_photons_);
    map(need.volume, "volume", "volume_photons", volume_photons_);
    if (largest > 0)
        parts.push_back(
            {"building the largest map's tree", photon_map_build_bytes(largest) - per * largest, largest_param});
    check_memory(type, W, H, parts);
}

bool PhotonMapper::photon_pass(PassLoop& loop, Maps& maps, std::vector<PhotonMapStats>& info,
                               ThreadStats& pstats) const {
    const Scene& scene = loop.scene();
    const RenderOptions& opts = loop.options();
    int threads = loop.threads();
    const SceneFeatures& f = scene.features;
    const MapNeeds need = needs(scene);
    Vec3 center;
    float radius;
    scene.bounding_sphere(center, radius);
    const std::function<bool()>& poll_once = loop.poll_once();
    // Traces one map's photons and files its stats; `make(photons)` builds
    // the tree(s) from them (false: cancelled). False when cancelled.
    auto trace_and_build = [&](const char* name, const PhotonTraceSpec& spec, uint64_t target, auto&& make) {
        PhotonPass pass = trace_photons_until(scene, spec, opts.seed, target, threads, poll_once, pstats);
        if (pass.cancelled) return false;
        PhotonMapStats s;
        s.name = name;
        s.photons = pass.photons.size();
        s.paths = pass.paths;
        s.trace_seconds = pass.seconds;
        s.target_reached = pass.target_reached;
        s.target = target;
        s.max_paths = pass.max_paths;
        auto tb = Clock::now();
        if (!make(std::move(pass.photons))) return false;
        s.build_seconds = since(tb);
        s.bytes_per_photon = double(PhotonMap::bytes_per_photon());
        info.push_back(s);
        return true;
    };
    auto build = [&](const char* name, const PhotonTraceSpec& spec, uint64_t target, PhotonMap& map) {
        return trace_and_build(name, spec, target, [&](std::vector<Photon>&& photons) {
            return map.build(std::move(photons), threads, false, poll_once);
        });
    };
    // Light-path segments a photon may need: at least one camera segment
    // follows it (two with final gathering, for the global map).
    auto spec_for = [&](uint64_t stream, int camera_segments) {
        PhotonTraceSpec spec;
        spec.max_depth = max_depth_ < 0 ? -1 : max_depth_ - camera_segments;
        spec.rr_depth = rr_depth_;
        spec.stream = stream;
        return spec;
    };
    if (need.caustic) {
        PhotonTraceSpec spec = spec_for(1, 1);
        spec.caustic_only = true;
        if (!build("caustic", spec, uint64_t(caustic_photons_), maps.caustic)) return false;
        maps.has_caustic = true;
        maps.r2_caustic = sqr(caustic_radius_ * radius);
    }
    if (need.global) {
        PhotonTraceSpec spec = spec_for(2, final_gather_ ? 2 : 1);
        spec.indirect_only = !final_gather_;
        if (!build("global", spec, uint64_t(global_photons_), maps.global)) return false;
        maps.has_global = true;
        maps.r2_global = sqr(global_radius_ * radius);
    }
    // The volume photon map, only in a scene with media, and only when the
    // volume or subsurface class is simulated: its photons (L X+ V) need a
    // light segment, one more vertex and the camera segment.
    maps.center = center;
    maps.radius = radius;
    if (need.volume) {
        PhotonTraceSpec spec = spec_for(3, 1);
        spec.volume = true;
        // One tree per medium (the photons are in path order, so each
        // tree's input, and hence the tree, depends on the seed alone).
        auto per_medium = [&](std::vector<Photon>&& photons) {
            std::vector<std::vector<Photon>> per(scene.media.size());
            for (const Photon& ph : photons) {
                int m = photon_medium(ph);
                if (m >= 0 && m < int(per.size())) per[m].push_back(ph);
            }
            photons = {};
            maps.volume.resize(per.size());
            for (size_t m = 0; m < per.size(); ++m)
                if (!maps.volume[m].build(std::move(per[m]), threads, false, poll_once)) return false;
            return true;
        };
        if (!trace_and_build("volume", spec, uint64_t(volume_photons_), per_medium)) return false;
        maps.has_volume = true;
        maps.r2_volume = sqr(volume_radius_ * radius);
    }
    // Ray-marching steps (scenes with media): step_size, or one mean free
    // path of the medium's densest channel (its majorant in a grid), at
    // most 1/16 of the scene's radius. The step moves the variance and the
    // time, not the expectation (jittered steps, exact or ratio-tracked
    // transmittance); one mean free path was the most efficient step measured
    // (docs/measurements.md).
    if (f.has_media) {
        maps.step.resize(scene.media.size());
        for (size_t m = 0; m < scene.media.size(); ++m) {
            const Medium& med = *scene.media[m];
            float st = max_component(med.homogeneous ? med.sigma_t : med.majorant);
            float auto_step = radius / 16.f;
            if (st > 0.f) auto_step = std::min(auto_step, 1.f / st);
            maps.step[m] = step_size_ > 0.f ? step_size_ : auto_step;
        }
    }
    return true;
}

namespace {

std::unique_ptr<Integrator> make_photonmapper(ParamReader& p) { return std::make_unique<PhotonMapper>(p); }

}  // namespace

}  // namespace rm
