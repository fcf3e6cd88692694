// The bodies of subpath.h's random_walk and light_subpath, as templates on
// the visitor: the one walk, which subpath.cpp compiles for the
// VertexVisitor of ptracer and bdpt, and photon_trace.cpp for its photon
// store, so that the store and the walk's constant arguments (no
// densities, no visitor indirection) are compiled into photon tracing's
// loop. `visit(path)` returns false to end the walk, as VertexVisitor's.
#pragma once
#include <algorithm>

#include "transport/subpath.h"

namespace rm {

// The shape an area emitter lies on (-1 for the others): where its light
// starts decides the medium it starts in (emitter_medium).
int emitter_shape(const Scene& scene, const Emitter& e);

// A vertex with every field at its default, copied into each new slot of
// the walk (a block copy, cheaper than member-by-member initialisation).
extern const PathVertex kFreshVertex;

// Each new vertex gets pdf_fwd and its predecessor's predecessor pdf_rev
// (Veach 1997, sec. 10.2.1), both through pdf_to from the vertex positions,
// exactly as the connections compute them: the weights are a partition of
// unity only if every strategy sees the same numbers (the sampled direction
// leaves an offset origin, and for vertices 1e-2 apart in a corner that
// moved densities by 1 %, measured by bdpt_mis_check). The walk's steps
// follow pbrt-v4's RandomWalk (bdpt.cpp) with SmallVCM's light loop
// (vertexcm.hxx): every vertex is handed to `visit` as it is made.
template <class Visit>
void random_walk_with(const Scene& scene, Sampler& sampler, Ray ray, Color beta, TransportMode mode, int max_vertices,
                      int rr_depth, std::vector<PathVertex>& path, ThreadStats& stats, Visit& visit,
                      const MediumTracker* media, bool densities) {
    BsdfContext ctx{mode};
    Color thr(1.f);         // throughput since the start (Russian roulette without media)
    float eta_scale = 1.f;  // undoes radiance scaling by eta^2 (Russian roulette)
    // Through media: the hero channel of spectral MIS (media_common.h),
    // drawn once per walk, and the medium the walk is in.
    MediumTracker mt = media ? *media : MediumTracker{};
    SpectralThroughput th(media ? std::min(int(sampler.next_1d() * 3.f), 2) : 0, beta);
    const float beta0 = max_component(beta);
    // The vertex just placed at the end of `path`: its densities (above),
    // then the visitor; false when the walk ends there (the visitor's
    // choice, or max_vertices reached).
    auto add_vertex = [&]() {
        const size_t n = path.size() - 1;  // index of v
        PathVertex& v = path[n];
        const PathVertex& prev = path[n - 1];
        if (densities && n == 1) {
            v.pdf_fwd = prev.type == VType::Camera ? camera_pdf_a(scene, prev, v) : pdf_to(scene, prev, nullptr, v);
        } else if (densities && prev.delta) {
            v.pdf_fwd = 0.f;  // a delta: remap0 in the weights (pbrt-v4)
            path[n - 2].pdf_rev = 0.f;
        } else if (densities) {
            v.pdf_fwd = pdf_to(scene, prev, &path[n - 2], v);
            path[n - 2].pdf_rev = pdf_to(scene, prev, &v, path[n - 2]);
        }
        if (!visit(path)) return false;
        return int(path.size()) < max_vertices;
    };
    // Russian roulette after the depth-th scattering vertex (common.h):
    // Mitsuba's rule on the throughput since the start, volpath's in media.
    auto roulette = [&](int depth, float rr_u) {
        if (media)
            return survives_roulette(RouletteRule::BelowStart, depth, rr_depth,
                                     beta0 > 0.f ? max_component(th.beta) / beta0 * eta_scale : 0.f, rr_u, th.beta);
        float q = roulette_survival(RouletteRule::Capped, depth, rr_depth, max_component(thr) * eta_scale);
        if (!(rr_u < q)) return false;
        th.beta /= q;
        thr /= q;
        return true;
    };
    // depth: scattering vertices from the start to the new vertex (every
    // surface vertex without media; null boundaries excluded with them).
    for (int depth = 1, guard = 0; guard < (1 << 20); ++guard) {
        if (int(path.size()) >= max_vertices) break;
        // 1. The next surface along the ray, intersected straight into the
        //    vertex it may become (no Interaction copied per bounce); the
        //    slot is reset or dropped when it becomes another vertex or none.
        PathVertex& v = path.emplace_back(kFreshVertex);
        Interaction& it = v.it;
        ++stats.rays;
        bool hit = scene.intersect(ray, it);

        // 2. Free flight through the current medium (media_common.h); a
        //    scattering event is a Medium vertex, whose next direction the
        //    phase function samples (weight eval / pdf = 1 for ours).
        if (media && mt.medium >= 0) {
            const Medium& med = *scene.media[mt.medium];
            float t = 0.f;
            FlightEvent event = free_flight(med, ray, hit ? it.t : ray.tmax, sampler, th, t);
            if (event == kAbsorbed) {
                path.pop_back();
                break;
            }
            if (event == kScattered) {
                v = kFreshVertex;
                v.type = VType::Medium;
                v.it.kind = VertexKind::Medium;
                v.it.valid = true;
                v.it.p = ray.o + ray.d * t;
                v.it.wi = -ray.d;
                v.it.t = t;
                v.beta = th.beta;
                v.phase = med.phase.get();
                v.medium = mt.medium;
                v.enclosed = mt.enclosed;
                if (!add_vertex()) break;
                PhaseSample ps = v.phase->sample(v.it.wi, sampler.next_2d());
                if (!(ps.pdf_w > 0.f)) break;
                th.beta *= ps.weight;
                ray = Ray{v.it.p, ps.wo, 0.f, kInf};
                if (!roulette(depth++, sampler.next_1d())) break;
                continue;
            }
        }

        // 3. Leaving the scene: a camera path ends on the environment, a
        //    Light vertex at infinity for the s = 0 strategy (pbrt-v4).
        if (!hit) {
            if (mode == TransportMode::Radiance && !scene.environment.empty()) {
                v = kFreshVertex;
                v.type = VType::Light;
                v.infinite = true;
                v.emitter = scene.environment[0];
                v.it.p = far_point(scene, ray);
                v.it.wi = -ray.d;
                v.beta = th.beta;
                v.medium = mt.medium;
                add_vertex();
            } else {
                path.pop_back();
            }
            break;
        }
        const Shape& shape = *scene.shapes[it.shape];
        const Bsdf* bsdf = scene.bsdfs[shape.bsdf].get();

        // 4. Through media, an index-matched boundary is no vertex: cross it.
        if (media && bsdf->flags() == kNull) {
            mt.cross(it, ray.d, true);
            ray = it.spawn(ray.d);
            path.pop_back();
            continue;
        }

        // 5. A surface vertex.
        v.beta = th.beta;
        v.bsdf = bsdf;
        v.emitter = shape.emitter >= 0 ? scene.emitters[shape.emitter].get() : nullptr;
        v.medium = mt.medium;
        if (!add_vertex()) break;

        // 6. Sample the next direction (adjoint BSDF with the shading-normal
        //    correction in importance transport, common.h); the medium
        //    changes when the sample crosses a boundary.
        Vec3 wi = it.to_local(it.wi);
        BsdfSample bs = v.bsdf->sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
        if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) break;
        Vec3 wo = it.to_world(bs.wo);
        Color f = bs.weight;
        if (mode == TransportMode::Importance)
            f *= shading_correction(it, it.wi, wo);
        else
            eta_scale *= sqr(bs.eta);
        th.beta *= f;
        thr *= f;
        v.delta = bs.is_delta;
        if (media) mt.cross(it, wo, false);
        ray = it.spawn(wo);

        // 7. Russian roulette.
        if (!roulette(depth++, sampler.next_1d())) break;
    }
}

template <class Visit>
bool light_subpath_with(const Scene& scene, Sampler& sampler, int max_vertices, int rr_depth,
                        std::vector<PathVertex>& light, EmissionSample& es, ThreadStats& stats, Visit& visit,
                        bool densities) {
    light.clear();
    // 1. An emitter picked (pick_start_emitter: by the render's light
    //    sampler, without a point) and a ray of light leaving it, its weight
    //    the flux Le |cos| / (pdf_a pdf_w) / pick (Jensen 2001, sec. 5.1);
    //    the same random numbers whatever happens.
    float u_pick = sampler.next_1d();
    Vec2 u_pos = sampler.next_2d();
    float u_extra = sampler.next_1d();
    Vec2 u_dir = sampler.next_2d();
    float pick = 0.f;
    const Emitter* e = pick_start_emitter(scene, u_pick, pick);
    if (!e) return false;
    Vec3 center;
    float radius;
    scene.bounding_sphere(center, radius);
    es = e->sample_emission(u_pos, u_extra, u_dir, center, radius);
    if (!(es.pdf_a > 0.f) || !(es.pdf_w > 0.f)) return false;
    // 2. y0 and its density. At infinity that is the density of its
    //    direction under light sampling (pbrt-v4's GenerateLightSubpath);
    //    y1's comes from the origin disk through emitter_pdf_to.
    PathVertex& y0 = light.emplace_back();
    y0.type = VType::Light;
    y0.emitter = e;
    y0.it.p = es.p;
    y0.it.n = es.n;
    y0.it.eps = es.eps;
    y0.pdf_fwd = pick * es.pdf_a;
    y0.infinite = e->is_infinite();
    if (y0.infinite && densities) {  // seen from a point downstream of y0, the light lies along -es.d
        PathVertex downstream;
        downstream.it.p = es.p + es.d;
        y0.pdf_fwd = light_origin_pdf(scene, y0, downstream);
    }
    // 3. The medium the light starts in, and the transmittance from
    //    infinity through it for an emitter at infinity.
    Ray ray;
    ray.o = es.p + es.n * es.eps;
    ray.d = es.d;
    MediumTracker mt;
    Color beta = es.weight / pick;
    if (scene.features.has_media) {
        mt = emitter_medium(scene, ray, es.n, emitter_shape(scene, *e));
        y0.medium = mt.medium;
        y0.enclosed = mt.enclosed;
        if (y0.infinite) beta *= transmittance_from_infinity(scene, mt.medium);
    }
    if (!visit(light)) return true;
    if (is_black(beta)) return true;  // y0 alone: light from infinity that no unbounded medium lets through
    // 4. The adjoint walk.
    random_walk_with(scene, sampler, ray, beta, TransportMode::Importance, max_vertices, rr_depth, light, stats, visit,
                     scene.features.has_media ? &mt : nullptr, densities);
    return true;
}

}  // namespace rm
