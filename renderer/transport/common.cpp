#include "transport/common.h"

namespace rm {

std::atomic<bool> g_shading_correction{true};

Color estimate_direct(const Scene& scene, const Interaction& it, const Bsdf& bsdf, const Vec3& wi_local,
                      Sampler& sampler, ThreadStats& stats, float light_frac, float bsdf_frac) {
    DirectSample ds;
    if (!sample_light(scene, light_context(it), sampler, ds)) return Color(0.f);
    BsdfContext ctx;
    ctx.set(it);
    Vec3 wo = it.to_local(ds.d);
    Color f = bsdf.eval(ctx, wi_local, wo);
    if (is_black(f)) return Color(0.f);
    ++stats.shadow_rays;
    if (!scene.visible(it, ds)) return Color(0.f);
    float light_pdf = ds.pdf_w * ds.pick;
    float w = ds.is_delta ? 1.f : mis_power(light_pdf * light_frac, bsdf.pdf_w(ctx, wi_local, wo) * bsdf_frac);
    return f * ds.radiance * (w / light_pdf);
}

bool trace_counting_emission(const Scene& scene, const Ray& ray, Interaction& it, const Color& beta, int cls,
                             bool count, EffectRadiance& out, ThreadStats& stats) {
    ++stats.rays;
    if (!scene.intersect(ray, it)) {
        if (count)
            for (const Emitter* e : scene.environment) out.add(cls, beta * e->eval_environment(ray.d));
        return false;
    }
    const Shape& shape = *scene.shapes[it.shape];
    if (shape.emitter >= 0 && count) out.add(cls, beta * scene.emitters[shape.emitter]->eval(it, it.wi));
    return true;
}

void add_emission_at_hit(const Scene& scene, const Ray& ray, const Interaction* it, const Color& beta, int cls,
                         int depth, bool prev_delta, const LightContext& prev_ctx, const Vec3& prev_p, float prev_pdf_w,
                         EffectRadiance& out) {
    const bool weighted = !(depth == 0 || prev_delta);
    if (!it) {
        for (const Emitter* e : scene.environment) {
            float w = weighted ? mis_emission_hit(scene, *e, prev_ctx, prev_p, nullptr, ray.d, prev_pdf_w) : 1.f;
            out.add(cls, beta * e->eval_environment(ray.d) * w);
        }
        return;
    }
    const Shape& shape = *scene.shapes[it->shape];
    if (shape.emitter < 0) return;
    const Emitter& e = *scene.emitters[shape.emitter];
    Color le = e.eval(*it, it->wi);
    if (is_black(le)) return;
    float w = weighted ? mis_emission_hit(scene, e, prev_ctx, prev_p, it, ray.d, prev_pdf_w) : 1.f;
    out.add(cls, beta * le * w);
}

float light_pdf_w(const Scene& scene, const Emitter& e, const LightContext& ctx, const Vec3& prev_p,
                  const Interaction* it, const Vec3& d) {
    float light_pdf = it ? e.pdf_direct(prev_p, it->p, it->n) : e.pdf_environment(d);
    return light_pdf * emitter_pick_prob(scene, ctx, e);
}

float mis_emission_hit(const Scene& scene, const Emitter& e, const LightContext& ctx, const Vec3& prev_p,
                       const Interaction* it, const Vec3& d, float bsdf_pdf_w, float light_frac, float bsdf_frac) {
    return mis_power(bsdf_pdf_w * bsdf_frac, light_pdf_w(scene, e, ctx, prev_p, it, d) * light_frac);
}

}  // namespace rm
