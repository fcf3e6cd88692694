// `direct`: direct illumination only (emission seen by the camera plus one
// bounce), combining emitter and BSDF samples with the power heuristic in
// Veach's multi-sample model (Veach 1997, sec. 9.2.2).
#include "render/registry.h"
#include "transport/common.h"
#include "transport/scatter_origin.h"

namespace rm {

namespace {

std::unique_ptr<Integrator> make_direct(ParamReader& p);

// Parameters, as Mitsuba 3's `direct` plugin.
[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "direct";
    e.doc = "direct illumination: emitter and BSDF samples combined by the power heuristic (Veach 1997, sec. 9.2.2)";
    e.params = {
        ParamSpec::integer("emitter_samples", 1, "light samples per camera sample").at_least(0),
        ParamSpec::integer("bsdf_samples", 1, "BSDF samples per camera sample").at_least(0),
        hide_emitters_param(),
        ParamSpec::setting("shading_samples", {"emitter_samples", "bsdf_samples"},
                           "Mitsuba's shorthand for both sample counts")
            .at_least(0),
    };
    e.caps.driver = Driver::Camera;
    e.caps.effects = effect_mask({kEmission, kDirect});
    e.factory = make_direct;
    return e;
}());

}  // namespace

class DirectIntegrator final : public Integrator {
public:
    explicit DirectIntegrator(ParamReader& p)
        : n_light_(p.get_int("emitter_samples")),
          n_bsdf_(p.get_int("bsdf_samples")),
          hide_(p.get_bool("hide_emitters")) {
        if (n_light_ + n_bsdf_ == 0)
            p.fail("emitter_samples", "emitter_samples and bsdf_samples must be >= 0, not both 0");
        float total = float(n_light_ + n_bsdf_);
        light_frac_ = n_light_ / total;
        bsdf_frac_ = n_bsdf_ / total;
    }

    void sample(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out,
                ThreadStats& stats) const override {
        Interaction it;
        bool hit = scene.intersect(ray, it);
        shade(scene, sampler, ray, hit ? &it : nullptr, out, stats);
    }

    // The camera driver traces the camera rays in packets (integrator.h).
    bool takes_camera_hits() const override { return true; }
    void sample_from_hit(const Scene& scene, Sampler& sampler, const Ray& ray, const Interaction* hit,
                         EffectRadiance& out, ThreadStats& stats) const override {
        shade(scene, sampler, ray, hit, out, stats);
    }

private:
    // Direct illumination at the camera ray's closest hit `first` (nullptr: none).
    void shade(const Scene& scene, Sampler& sampler, const Ray& ray, const Interaction* first, EffectRadiance& out,
               ThreadStats& stats) const {
        // 1. The camera ray, and emission it sees directly.
        ++stats.rays;
        if (!first) {
            if (!hide_ && mask[kEmission])
                for (const Emitter* e : scene.environment) out.add(kEmission, e->eval_environment(ray.d));
            return;
        }
        const Interaction& it = *first;
        const Shape& shape = *scene.shapes[it.shape];
        if (shape.emitter >= 0 && !hide_ && mask[kEmission])
            out.add(kEmission, scene.emitters[shape.emitter]->eval(it, it.wi));
        if (!mask[kDirect] && !mask[kSpecular]) return;
        const Bsdf& bsdf = *scene.bsdfs[shape.bsdf];
        Vec3 wi = it.to_local(it.wi);
        BsdfContext ctx;
        ctx.set(it);

        // 2. Emitter samples (smooth lobes only), each weighted 1 / n_light.
        if (bsdf.has_smooth() && mask[kDirect])
            for (int i = 0; i < n_light_; ++i) {
                Color ld = estimate_direct(scene, it, bsdf, wi, sampler, stats, light_frac_, bsdf_frac_);
                out.add(kDirect, ld / float(n_light_));
            }

        // 3. BSDF samples that reach an emitter, each weighted 1 / n_bsdf.
        ScatterOrigin origin;
        origin.set(it, wi, &bsdf);
        for (int i = 0; i < n_bsdf_; ++i) {
            BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) continue;
            int cls = bs.is_delta ? kSpecular : kDirect;
            if (!mask[cls]) continue;
            Ray r = it.spawn(it.to_world(bs.wo));
            Interaction hit2;
            ++stats.rays;
            Color c(0.f);
            if (!scene.intersect(r, hit2)) {
                for (const Emitter* e : scene.environment) {
                    float w = bs.is_delta ? 1.f
                                          : mis_emission_hit(scene, *e, light_context(it), r.o, nullptr, r.d, bs.pdf_w,
                                                             light_frac_, bsdf_frac_);
                    c += e->eval_environment(r.d) * w;
                }
            } else if (scene.shapes[hit2.shape]->emitter >= 0) {
                const Emitter& e = *scene.emitters[scene.shapes[hit2.shape]->emitter];
                Color le = e.eval(hit2, hit2.wi);
                if (!is_black(le)) {
                    // Both densities from it.p, as estimate_direct's (scatter_origin.h).
                    float w = bs.is_delta ? 1.f
                                          : mis_emission_hit(scene, e, light_context(it), it.p, &hit2, r.d,
                                                             origin.pdf_to(hit2.p, bs.pdf_w), light_frac_, bsdf_frac_);
                    c += le * w;
                }
            }
            out.add(cls, bs.weight * c / float(n_bsdf_));
        }
    }

    int n_light_, n_bsdf_;
    bool hide_;
    float light_frac_, bsdf_frac_;
};

namespace {

std::unique_ptr<Integrator> make_direct(ParamReader& p) { return std::make_unique<DirectIntegrator>(p); }

}  // namespace

}  // namespace rm
