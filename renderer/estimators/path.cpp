// `path`: unidirectional path tracing (Kajiya 1986) with next event estimation
// and BSDF sampling combined by the power heuristic (Veach 1997, ch. 9), and
// Russian roulette. Parameters: the registration below (Mitsuba 3's `path`
// plugin's).
// Structure after pbrt-v4's PathIntegrator::Li (integrators.cpp): one loop,
// direct lighting in its own helper (common.cpp).
// `volpath` is this estimator under another name (DESIGN: "volpath, alias of
// path with media"): a scene with media (Scene::features.has_media) is
// rendered by the media-aware loop of volpath.cpp (for_scene hands it over,
// once per render); a scene without media runs the surface loop below,
// which has no media code at all.
// A shape with a dipole BSSRDF (scene/dipole.h) is handled by
// dipole_step (specular reflection or a sampled exit point, the path going
// on from there with the exit lobe as its BSDF): step 4a.
#include "estimators/volpath.h"
#include "render/registry.h"
#include "transport/common.h"
#include "transport/dipole_step.h"
#include "transport/scatter_origin.h"

namespace rm {

namespace {

std::unique_ptr<Integrator> make_path(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "path";
    // Mitsuba 3's `volpathmis` is its volumetric path tracer with spectral
    // MIS (Miller, Georgiev and Jarosz 2019), which volpath.cpp's loop is
    // too (hero channel, one-sample balance heuristic over the channels),
    // with the same parameters (max_depth, rr_depth, hide_emitters).
    e.aliases = {"volpath", "volpathmis"};
    e.doc =
        "unidirectional path tracing with next event estimation and MIS (Kajiya 1986; Veach 1997, ch. 9); "
        "media through volpath's loop";
    e.params = {
        max_depth_param().described("longest path in segments (1: only emitters seen directly; 2: direct "
                                    "illumination); in media, scattering vertices"),
        rr_depth_param(),
        hide_emitters_param(),
        truncation_probe_param(),
        equiangular_param(),
    };
    e.caps.media = true;
    e.caps.dipole = true;
    e.caps.driver = Driver::Camera;
    e.factory = make_path;
    return e;
}());

}  // namespace

class PathIntegrator final : public Integrator {
public:
    explicit PathIntegrator(const VolPathParams& prm)
        : max_depth_(prm.max_depth),
          rr_depth_(prm.rr_depth),
          hide_(prm.hide),
          probe_(prm.truncation_probe),
          media_(make_volpath_integrator(prm)) {}

    const Integrator& for_scene(const Scene& scene) const override {
        if (!scene.features.has_media) return *this;
        if (scene.features.has_masked_smooth)
            throw std::invalid_argument(
                "integrator '" + type +
                "' cannot render a 'mask' BSDF over a smooth BSDF in a scene with media (its media loop samples "
                "null lobes before next event estimation); use 'bdpt' or 'ptracer', or a scene without media");
        media_->mask = mask;
        media_->type = type;
        media_->caps = caps;
        return *media_;
    }

    void sample(const Scene& scene, Sampler& sampler, const Ray& camera_ray, EffectRadiance& out,
                ThreadStats& stats) const override {
        trace(scene, sampler, camera_ray, false, nullptr, out, stats);
    }

    // The camera driver traces the camera rays in packets (integrator.h).
    bool takes_camera_hits() const override { return true; }
    void sample_from_hit(const Scene& scene, Sampler& sampler, const Ray& camera_ray, const Interaction* hit,
                         EffectRadiance& out, ThreadStats& stats) const override {
        trace(scene, sampler, camera_ray, true, hit, out, stats);
    }

private:
    // The path from `camera_ray`; with `given`, its closest hit is `first`
    // (nullptr: none), already traced by the driver.
    void trace(const Scene& scene, Sampler& sampler, const Ray& camera_ray, bool given, const Interaction* first,
               EffectRadiance& out, ThreadStats& stats) const {
        Ray ray = camera_ray;
        Color beta(1.f);
        float eta_scale = 1.f;  // undoes radiance scaling by eta^2 for Russian roulette
        PathClass pc;
        float prev_pdf_w = 0.f;
        bool prev_delta = true;
        ScatterOrigin prev;       // the vertex the current ray left (scatter_origin.h)
        LightContext prev_ctx{};  // where the light sample competing with the BSDF sample was selected from
        BsdfContext ctx;
        // Where contributions go: the image, or, once the truncation probe
        // continued the path past max_depth, the light it would have cut off.
        EffectRadiance tail;
        EffectRadiance* sink = &out;
        for (int depth = 0;; ++depth) {
            // 1. Find the next vertex (its draws start at the bounce's own
            //    dimensions, for structured samplers: rng.h).
            sampler.start_bounce(depth);
            Interaction it;
            ++stats.rays;
            bool hit;
            if (depth == 0 && given) {
                hit = first != nullptr;
                if (hit) it = *first;
            } else {
                hit = scene.intersect(ray, it);
            }
            bool count_emission = !(depth == 0 && hide_);
            int cls = pc.classify();

            // 2. Emission reached by the previous BSDF sample (or the camera ray),
            //    weighted against next event estimation unless that sample was delta.
            if (count_emission && mask[cls]) {
                float pdf_w = prev_pdf_w;
                if (hit && !prev_delta && scene.shapes[it.shape]->emitter >= 0) pdf_w = prev.pdf_to(it.p, prev_pdf_w);
                add_emission_at_hit(scene, ray, hit ? &it : nullptr, beta, cls, depth, prev_delta, prev_ctx, prev.p,
                                    pdf_w, *sink);
            }
            if (!hit) break;
            const Shape& shape = *scene.shapes[it.shape];

            // 3. Stop at max_depth (Mitsuba's meaning: depth + 1 segments so far),
            //    or when no requested effect class is reachable any more.
            // The truncation probe (volpath.h): a fraction `probe_` of the
            //    paths stopped here go on, weighted 1 / probe_, into `tail`;
            //    its draw follows every draw of the path's first max_depth
            //    segments, so the image keeps its bytes.
            if (max_depth_ >= 0 && depth + 1 >= max_depth_ && sink == &out) {
                if (!(probe_ > 0.f) || !(sampler.next_1d() < probe_)) break;
                beta /= probe_;
                sink = &tail;
            }
            if (!pc.can_reach(mask, scene.features.has_dipole)) break;
            const Bsdf* bsdf = scene.bsdfs[shape.bsdf].get();
            Vec3 wi = it.to_local(it.wi);
            ctx.set(it);
            BsdfSample bs;
            bool sampled = false;

            // 4a. A dipole BSSRDF (dipole_step.h): specular reflection, or the
            //     subsurface exit point xi, where the path goes on (a B vertex)
            //     with the exit lobe Sw as its BSDF.
            if (shape.dipole >= 0 && !camera_dipole_vertex(scene, *scene.dipoles[shape.dipole], it, sampler, stats,
                                                           beta, pc, bsdf, wi, bs, sampled))
                break;

            if (!sampled) {
                // 4. Next event estimation (smooth lobes only).
                if (bsdf->has_smooth() && !scene.emitters.empty()) {
                    PathClass pn = pc;
                    pn.push(false);
                    int ncls = pn.classify();
                    if (mask[ncls]) {
                        Color ld = estimate_direct(scene, it, *bsdf, wi, sampler, stats);
                        sink->add(ncls, beta * ld);
                    } else {
                        // Keep the random-number stream aligned whatever the mask is.
                        sampler.next_1d();
                        sampler.next_2d();
                        sampler.next_1d();
                    }
                }
                // 5. Sample the BSDF for the next direction.
                bs = bsdf->sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
            }
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) break;
            beta *= bs.weight;
            eta_scale *= sqr(bs.eta);
            // An index-matched boundary (null) passes light unchanged: it is no
            // vertex of the path's class, though it counts towards max_depth as in Mitsuba's `path`.
            if (bsdf->flags() != kNull) pc.push(bs.is_delta);
            prev_pdf_w = bs.pdf_w;
            prev_delta = bs.is_delta;
            prev.set(it, wi, bsdf);
            ray = it.spawn(it.to_world(bs.wo));
            prev_ctx = light_context(it);

            // 6. Russian roulette (Mitsuba's rule, common.h).
            if (!survives_roulette(RouletteRule::Capped, depth + 1, rr_depth_, max_component(beta) * eta_scale,
                                   sampler.next_1d(), beta))
                break;
        }
        if (sink == &tail) {
            Color t = tail.total();
            if (is_finite(t)) stats.add_truncated(t);
        }
    }

    int max_depth_, rr_depth_;
    bool hide_;
    float probe_;
    std::unique_ptr<Integrator> media_;  // the media-aware twin (volpath.cpp)
};

namespace {

std::unique_ptr<Integrator> make_path(ParamReader& p) {
    VolPathParams prm;
    prm.max_depth = p.get_int("max_depth");
    prm.rr_depth = p.get_int("rr_depth");
    prm.hide = p.get_bool("hide_emitters");
    prm.truncation_probe = p.get_float("truncation_probe");
    prm.equiangular = p.get_bool("equiangular");
    return std::make_unique<PathIntegrator>(prm);
}

}  // namespace

}  // namespace rm
