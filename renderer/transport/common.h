// Pieces shared by the estimators: emitter selection, Russian roulette,
// next event estimation with MIS, emission found by BSDF sampling.
#pragma once
#include <atomic>

#include "render/integrator.h"

namespace rm {

// Emitter selection, by the sampler of the render in progress
// (scene/light_sampler.h; every estimator's `light_sampler` parameter).
// Seen from a point: a LightContext, the point and its geometric normal
// (zero in a medium), which the tree's probabilities depend on; the same
// context must reach every place the probability of the same selection
// is needed (the light sample, and the MIS weight of the emitter that a
// BSDF sample from that point finds).
struct LightContext {
    Vec3 p, n;
};
inline LightContext light_context(const Interaction& it) {
    return {it.p, it.kind == VertexKind::Medium ? Vec3(0.f) : it.n};
}
// The emitter u in [0, 1) picks from `ctx`, its probability in `pick`;
// null when none (no emitters, or none lights the point).
inline const Emitter* pick_emitter(const Scene& s, const LightContext& ctx, float u, float& pick) {
    int i = s.lights().sample(ctx.p, ctx.n, u, pick);
    return i < 0 ? nullptr : s.emitters[size_t(i)].get();
}
// The probability that pick_emitter from `ctx` picks `e`.
inline float emitter_pick_prob(const Scene& s, const LightContext& ctx, const Emitter& e) {
    return s.lights().pmf(ctx.p, ctx.n, e.index);
}
// A light path's start, seen from nowhere: by power under `power` and
// `tree`, uniform under `uniform` (LightSampler::sample_start).
inline const Emitter* pick_start_emitter(const Scene& s, float u, float& pick) {
    int i = s.lights().sample_start(u, pick);
    return i < 0 ? nullptr : s.emitters[size_t(i)].get();
}
inline float start_pick_prob(const Scene& s, const Emitter& e) { return s.lights().pmf_start(e.index); }
// The area density p_LE with which a light path starts at p on the area
// emitter e, its selection included (the MIS weights of bdpt and vcm).
inline float emission_origin_pdf(const Scene& s, const Emitter& e, const Vec3& p) {
    return start_pick_prob(s, e) * e.pdf_emission_a(p);
}

// Russian roulette (Arvo and Kirk 1990; Veach 1997, sec. 2.6.2): after a
// path's depth-th scattering vertex it goes on with probability q, its
// weight divided by q. `throughput`: the largest channel of the path's
// throughput relative to its start, times eta^2 in radiance transport
// (undoing the 1 / eta^2 scaling of refraction, as Mitsuba and pbrt-v4 do).
// Two rules, both kept because each one's estimators keep their streams:
//   Capped      Mitsuba's q = min(throughput, 0.95) from depth rr_depth on
//               (surface estimators, and subpaths through scenes without
//               media);
//   BelowStart  pbrt-v4's: q = throughput only once it has fallen below 1,
//               with the 0.95 cap only beyond kLongWalk vertices (walks
//               through media: volpath, the subpaths and photons in media).
//               In a medium the analog walk already ends paths by
//               absorption, and a 5 % kill per event on top multiplies the
//               weight of a long walk (hundreds of events in a dense, bright
//               medium) by 1 / 0.95^n, a heavy tail (measured on
//               translucent_slab: docs/measurements.md). The cap beyond kLongWalk ends a walk
//               in a white medium (albedo 1, which never absorbs) with
//               max_depth -1 in about 20 more events instead of
//               (size * sigma_t)^2.
// Returns q (1 before rr_depth; NaN throughput gives NaN, which ends the path).
enum class RouletteRule { Capped, BelowStart };
constexpr int kLongWalk = 1024;
inline float roulette_survival(RouletteRule rule, int depth, int rr_depth, float throughput) {
    if (depth < rr_depth) return 1.f;
    if (rule == RouletteRule::Capped) return std::min(throughput, 0.95f);
    float q = depth >= kLongWalk ? std::min(throughput, 0.95f) : throughput;
    return q >= 1.f ? 1.f : q;
}
// The roulette with random number u: false when the path ends, else `beta`
// divided by the survival probability.
inline bool survives_roulette(RouletteRule rule, int depth, int rr_depth, float throughput, float u, Color& beta) {
    float q = roulette_survival(rule, depth, rr_depth, throughput);
    if (!(u < q)) return false;
    beta /= q;
    return true;
}

// Light sampling from ctx.p: an emitter picked (pick_emitter; its
// probability in ds.pick) and a point on it (or a direction to it), for
// given random numbers (u_pick picks the emitter). False when the scene
// has no emitter or the sample carries nothing.
// `picked`, when given, receives the emitter.
inline bool sample_light(const Scene& scene, const LightContext& ctx, float u_pick, Vec2 u, float u_extra,
                         DirectSample& ds, const Emitter** picked = nullptr) {
    float pick = 0.f;
    const Emitter* e = pick_emitter(scene, ctx, u_pick, pick);
    if (picked) *picked = e;
    if (!e) return false;
    ds = e->sample_direct(ctx.p, u, u_extra);
    ds.pick = pick;
    return ds.pdf_w > 0.f && !is_black(ds.radiance);
}
// The same with 4 random numbers from `sampler` (always drawn).
inline bool sample_light(const Scene& scene, const LightContext& ctx, Sampler& sampler, DirectSample& ds,
                         const Emitter** picked = nullptr) {
    float u_pick = sampler.next_1d();
    Vec2 u = sampler.next_2d();
    float u_extra = sampler.next_1d();
    return sample_light(scene, ctx, u_pick, u, u_extra, ds, picked);
}

// Solid-angle density with which sample_light from `ctx` reaches emitter
// `e` at `it` (an area emitter's point), or along a direction to the
// environment (`it` null) along the unit direction d, the emitter's pick
// included; the point on the emitter is seen from `prev_p` (ctx.p, or
// the ray origin offset from it that found the emitter).
float light_pdf_w(const Scene& scene, const Emitter& e, const LightContext& ctx, const Vec3& prev_p,
                  const Interaction* it, const Vec3& d);

// Next event estimation at `it` (Veach 1997, sec. 9.2: light sample weighted by
// the power heuristic against BSDF sampling). Returns the contribution before
// the path throughput; `light_frac`/`bsdf_frac` are the one-sample-model
// fractions of Mitsuba's `direct` integrator (1, 1 for `path`).
Color estimate_direct(const Scene& scene, const Interaction& it, const Bsdf& bsdf, const Vec3& wi_local,
                      Sampler& sampler, ThreadStats& stats, float light_frac = 1.f, float bsdf_frac = 1.f);

// MIS weight of emission reached by a BSDF sample of density bsdf_pdf_w from
// `prev` (ctx and prev_p as light_pdf_w's), landing on `it` (an area
// emitter) or escaping along the unit direction d.
float mis_emission_hit(const Scene& scene, const Emitter& e, const LightContext& ctx, const Vec3& prev_p,
                       const Interaction* it, const Vec3& d, float bsdf_pdf_w, float light_frac = 1.f,
                       float bsdf_frac = 1.f);

// Emission a camera path's last sample reached (path.cpp, volpath.cpp):
// what the environment shows along `ray` when the ray left the scene (`it`
// null), else the hit shape's area emitter, times `beta`, under class
// `cls`; weighted by the power heuristic against next event estimation
// (mis_emission_hit, from prev_ctx and prev_p) unless the sample came from
// the camera (depth 0) or a delta lobe.
void add_emission_at_hit(const Scene& scene, const Ray& ray, const Interaction* it, const Color& beta, int cls,
                         int depth, bool prev_delta, const LightContext& prev_ctx, const Vec3& prev_p, float prev_pdf_w,
                         EffectRadiance& out);

// One step of a camera path for estimators that take emission found along
// it without an MIS weight (photonmapper, sppm, whitted: their only other route to
// the emitters is light sampling at non-specular vertices): intersects
// `ray`, and when `count` adds what the emitters it reaches show, times
// `beta`, under class `cls`. Returns false when the ray left the scene.
bool trace_counting_emission(const Scene& scene, const Ray& ray, Interaction& it, const Color& beta, int cls,
                             bool count, EffectRadiance& out, ThreadStats& stats);

// A camera path through delta lobes only (the specular chain L ... S* E of
// photonmapper, sppm and whitted, whose light at non-specular vertices comes
// from elsewhere: light sampling, photon maps): each segment counts the
// emission it reaches (trace_counting_emission, hidden at depth 0 when
// `hide`), the path stops after `max_depth` segments (< 0: no limit), and at
// every vertex `visit(it, bsdf, wi, beta, pc, depth)` does the estimator's
// work and returns whether to go on. Going on samples the BSDF: a delta
// sample continues the chain (beta times its weight, a non-null vertex
// counted as specular in `pc`), anything else ends it (a smooth lobe's light
// is the visitor's to estimate; the lobe-selection weight keeps the sum
// unbiased). With rr_depth >= 0 the chain plays Russian roulette after
// each vertex (RouletteRule::Capped).
struct SpecularChain {  // SpecularChain{max_depth, rr_depth, hide}
    int max_depth = -1;
    int rr_depth = -1;
    bool hide = false;
};

template <class Visit>
void walk_specular_chain(const Scene& scene, Sampler& sampler, Ray ray, const SpecularChain& chain,
                         const EffectMask& mask, EffectRadiance& out, ThreadStats& stats, Visit&& visit) {
    Color beta(1.f);
    PathClass pc;
    BsdfContext ctx;
    for (int depth = 0;; ++depth) {
        Interaction it;
        int cls = pc.classify();
        if (!trace_counting_emission(scene, ray, it, beta, cls, !(depth == 0 && chain.hide) && mask[cls], out, stats))
            return;
        if (chain.max_depth >= 0 && depth + 1 >= chain.max_depth) return;
        const Bsdf& bsdf = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
        Vec3 wi = it.to_local(it.wi);
        if (!visit(static_cast<const Interaction&>(it), bsdf, wi, static_cast<const Color&>(beta),
                   static_cast<const PathClass&>(pc), depth))
            return;
        ctx.set(it);
        BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
        if (!(bs.pdf_w > 0.f) || is_black(bs.weight) || !bs.is_delta) return;
        beta *= bs.weight;
        if (bsdf.flags() != kNull) pc.push(true);
        ray = it.spawn(it.to_world(bs.wo));
        if (chain.rr_depth >= 0 && !survives_roulette(RouletteRule::Capped, depth + 1, chain.rr_depth,
                                                      max_component(beta), sampler.next_1d(), beta))
            return;
    }
}

// Adjoint BSDF with shading normals (Veach 1997, eq. 5.16; pbrt-v3's
// CorrectShadingNormal): in importance transport a vertex that scatters
// from wi (towards the light) to wo weights f |wo.ns| (what eval/sample
// give) by |wi.ns| |wo.ng| / (|wi.ng| |wo.ns|). Used by ptracer and bdpt.
// Test hook (bindings/test_hooks.cpp): false drops the correction, so that
// tests/test_normalmap.py can show its light-versus-camera comparison sees it.
extern std::atomic<bool> g_shading_correction;
inline float shading_correction(const Interaction& it, const Vec3& wi, const Vec3& wo) {
    if (!g_shading_correction.load(std::memory_order_relaxed)) return 1.f;
    float num = absdot(wi, it.sh.n) * absdot(wo, it.n);
    float den = absdot(wi, it.n) * absdot(wo, it.sh.n);
    return den > 0.f ? num / den : 0.f;
}

}  // namespace rm
