// Pieces shared by the surface estimators: emitter selection, next event
// estimation with MIS, emission found by BSDF sampling.
#pragma once
#include "render/integrator.h"

namespace rm {

// Uniform emitter selection, as Mitsuba 3's Scene::sample_emitter_direction.
inline float emitter_pick_prob(const Scene& s) { return s.emitters.empty() ? 0.f : 1.f / float(s.emitters.size()); }

// Light sampling from `p`: an emitter picked uniformly and a point on it
// (or a direction to it); always draws the same 4 random numbers. False
// when the scene has no emitter or the sample carries nothing.
bool sample_light(const Scene& scene, const Vec3& p, Sampler& sampler, DirectSample& ds);
// The same for given random numbers (u_pick picks the emitter).
bool sample_light(const Scene& scene, const Vec3& p, float u_pick, Vec2 u, float u_extra, DirectSample& ds);

// Solid-angle density with which sample_light from `prev_p` reaches emitter
// `e` at `it` (an area emitter's point), or along a direction to the
// environment (`it` null), the emitter's pick included.
float light_pdf_w(const Scene& scene, const Emitter& e, const Vec3& prev_p, const Interaction* it);

// Next event estimation at `it` (Veach 1997, sec. 9.2: light sample weighted by
// the power heuristic against BSDF sampling). Returns the contribution before
// the path throughput; `light_frac`/`bsdf_frac` are the one-sample-model
// fractions of Mitsuba's `direct` integrator (1, 1 for `path`).
Color estimate_direct(const Scene& scene, const Interaction& it, const Bsdf& bsdf, const Vec3& wi_local,
                      Sampler& sampler, ThreadStats& stats, float light_frac = 1.f, float bsdf_frac = 1.f);

// MIS weight of emission reached by a BSDF sample of density bsdf_pdf_w from
// `prev`, landing on `it` (an area emitter) or escaping along d.
float mis_emission_hit(const Scene& scene, const Emitter& e, const Vec3& prev_p, const Interaction* it,
                       float bsdf_pdf_w, float light_frac = 1.f, float bsdf_frac = 1.f);

// Emission a camera path's last sample reached (path.cpp, volpath.cpp):
// what the environment shows along `ray` when the ray left the scene (`it`
// null), else the hit shape's area emitter, times `beta`, under class
// `cls`; weighted by the power heuristic against next event estimation
// (mis_emission_hit) unless the sample came from the camera (depth 0) or a
// delta lobe.
void add_emission_at_hit(const Scene& scene, const Ray& ray, const Interaction* it, const Color& beta, int cls,
                         int depth, bool prev_delta, const Vec3& prev_p, float prev_pdf_w, EffectRadiance& out);

// One step of a camera path for estimators that take emission found along
// it without an MIS weight (photonmapper, sppm: their only other route to
// the emitters is light sampling at non-specular vertices): intersects
// `ray`, and when `count` adds what the emitters it reaches show, times
// `beta`, under class `cls`. Returns false when the ray left the scene.
bool trace_counting_emission(const Scene& scene, const Ray& ray, Interaction& it, const Color& beta, int cls,
                             bool count, EffectRadiance& out, ThreadStats& stats);

// Adjoint BSDF with shading normals (Veach 1997, eq. 5.16; pbrt-v3's
// CorrectShadingNormal): in importance transport a vertex that scatters
// from wi (towards the light) to wo weights f |wo.ns| (what eval/sample
// give) by |wi.ns| |wo.ng| / (|wi.ng| |wo.ns|). Used by ptracer and bdpt.
inline float shading_correction(const Interaction& it, const Vec3& wi, const Vec3& wo) {
    float num = absdot(wi, it.sh.n) * absdot(wo, it.n);
    float den = absdot(wi, it.n) * absdot(wo, it.sh.n);
    return den > 0.f ? num / den : 0.f;
}

}  // namespace rm
