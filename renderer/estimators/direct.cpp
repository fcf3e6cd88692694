// `direct`: direct illumination only (emission seen by the camera plus one
// bounce), combining emitter and BSDF samples with the power heuristic in
// Veach's multi-sample model (Veach 1997, sec. 9.2.2). Parameters, as Mitsuba
// 3's `direct` plugin:
//   emitter_samples  light samples per camera sample (default 1)
//   bsdf_samples     BSDF samples per camera sample (default 1)
//   hide_emitters    directly visible emitters appear black
#include "transport/common.h"

#include <stdexcept>

namespace rm {

class DirectIntegrator final : public Integrator {
public:
    explicit DirectIntegrator(const IntegratorDesc& d)
        : n_light_(d.emitter_samples), n_bsdf_(d.bsdf_samples), hide_(d.hide_emitters) {
        float total = float(n_light_ + n_bsdf_);
        light_frac_ = n_light_ / total;
        bsdf_frac_ = n_bsdf_ / total;
    }

    void sample(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out,
                ThreadStats& stats) const override {
        // 1. The camera ray, and emission it sees directly.
        Interaction it;
        ++stats.rays;
        bool hit = scene.intersect(ray, it);
        if (!hit) {
            if (!hide_ && mask[kEmission])
                for (const Emitter* e : scene.environment) out.add(kEmission, e->eval_environment(ray.d));
            return;
        }
        const Shape& shape = *scene.shapes[it.shape];
        if (shape.emitter >= 0 && !hide_ && mask[kEmission])
            out.add(kEmission, scene.emitters[shape.emitter]->eval(it, it.wi));
        if (!mask[kDirect] && !mask[kSpecular]) return;
        const Bsdf& bsdf = *scene.bsdfs[shape.bsdf];
        Vec3 wi = it.to_local(it.wi);
        BsdfContext ctx;

        // 2. Emitter samples (smooth lobes only), each weighted 1 / n_light.
        if (bsdf.has_smooth() && mask[kDirect])
            for (int i = 0; i < n_light_; ++i) {
                Color ld = estimate_direct(scene, it, bsdf, wi, sampler, stats, light_frac_, bsdf_frac_);
                out.add(kDirect, ld / float(n_light_));
            }

        // 3. BSDF samples that reach an emitter, each weighted 1 / n_bsdf.
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
                    float w = bs.is_delta ? 1.f : mis_emission_hit(scene, *e, r.o, nullptr, bs.pdf_w, light_frac_, bsdf_frac_);
                    c += e->eval_environment(r.d) * w;
                }
            } else if (scene.shapes[hit2.shape]->emitter >= 0) {
                const Emitter& e = *scene.emitters[scene.shapes[hit2.shape]->emitter];
                Color le = e.eval(hit2, hit2.wi);
                if (!is_black(le)) {
                    float w = bs.is_delta ? 1.f : mis_emission_hit(scene, e, r.o, &hit2, bs.pdf_w, light_frac_, bsdf_frac_);
                    c += le * w;
                }
            }
            out.add(cls, bs.weight * c / float(n_bsdf_));
        }
    }

private:
    int n_light_, n_bsdf_;
    bool hide_;
    float light_frac_, bsdf_frac_;
};

std::unique_ptr<Integrator> make_path_integrator(const IntegratorDesc& d);
std::unique_ptr<Integrator> make_ptracer_integrator(const IntegratorDesc& d);
std::unique_ptr<Integrator> make_bdpt_integrator(const IntegratorDesc& d);
std::unique_ptr<Integrator> make_photonmapper_integrator(const IntegratorDesc& d);
std::unique_ptr<Integrator> make_sppm_integrator(const IntegratorDesc& d);

std::unique_ptr<Integrator> make_integrator(const IntegratorDesc& d, const EffectMask& mask) {
    std::unique_ptr<Integrator> r;
    if (d.max_depth < -1 || d.max_depth == 0)
        throw std::invalid_argument("integrator '" + d.type + "': max_depth must be -1 (unbounded) or >= 1");
    if (d.rr_depth < 1) throw std::invalid_argument("integrator '" + d.type + "': rr_depth must be >= 1");
    if (d.type == "path" || d.type == "volpath") {
        r = make_path_integrator(d);
    } else if (d.type == "ptracer") {
        r = make_ptracer_integrator(d);
    } else if (d.type == "bdpt") {
        r = make_bdpt_integrator(d);
    } else if (d.type == "photonmapper") {
        r = make_photonmapper_integrator(d);
    } else if (d.type == "sppm") {
        r = make_sppm_integrator(d);
    } else if (d.type == "direct") {
        if (d.emitter_samples < 0 || d.bsdf_samples < 0 || d.emitter_samples + d.bsdf_samples == 0)
            throw std::invalid_argument("integrator 'direct': emitter_samples and bsdf_samples must be >= 0, not both 0");
        r = std::make_unique<DirectIntegrator>(d);
    } else {
        throw std::invalid_argument("integrator '" + d.type + "' is not implemented yet");
    }
    r->mask = mask;
    r->type = d.type;
    return r;
}

}  // namespace rm
