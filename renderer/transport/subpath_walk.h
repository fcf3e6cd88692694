// The bodies of subpath.h's random_walk and light_subpath, as templates on
// the visitor: the one walk, which subpath.cpp compiles for the
// VertexVisitor of ptracer and bdpt, and photon_trace.cpp for its photon
// store, so that the store and the walk's constant arguments (no
// densities, no visitor indirection) are compiled into photon tracing's
// loop. `visit(path)` returns false to end the walk, as VertexVisitor's.
#pragma once
#include <algorithm>
#include <utility>

#include "transport/subpath.h"

namespace rm {

// The shape an area emitter lies on (-1 for the others): where its light
// starts decides the medium it starts in (emitter_medium).
int emitter_shape(const Scene& scene, const Emitter& e);

// A vertex with every field at its default, copied into each new slot of
// the walk (a block copy, cheaper than member-by-member initialisation).
extern const PathVertex kFreshVertex;

// A visitor that declares `static constexpr bool kLastTwo = true` walks in
// the window mode: `path` holds two slots, the new vertex and the one
// before it (vertex i in slot i & 1), and the visitor is called as
// visit(v, prev, i) with prev null for the start vertex i = 0. For a
// visitor that reads only a vertex and its predecessor (photon storage):
// no vertex record is copied per vertex, a reused slot gets only the
// fields the walk does not write at a surface vertex reset, and there are
// no densities (they read the vertex two back). A surface vertex's
// `emitter` is not set, and y0 holds the fields light_subpath_with
// writes (its interaction p, n and eps). The walk's arithmetic and random
// numbers are the same in both modes.
template <class V, class = void>
struct WalksLastTwo : std::false_type {};
template <class V>
struct WalksLastTwo<V, std::void_t<decltype(V::kLastTwo)>> : std::bool_constant<V::kLastTwo> {};

// A reused slot made a fresh surface vertex: every field that
// Scene::intersect (the whole Interaction on a hit) and step 5 of the walk
// do not write, to its default.
inline void reset_walk_slot(PathVertex& v) {
    v.type = VType::Surface;
    v.pdf_fwd = 0.f;
    v.pdf_rev = 0.f;
    v.delta = false;
    v.infinite = false;
    v.phase = nullptr;
    v.enclosed = false;
}

// Each new vertex gets pdf_fwd and its predecessor's predecessor pdf_rev
// (Veach 1997, sec. 10.2.1), both through pdf_to from the vertex positions,
// exactly as the connections compute them: the weights are a partition of
// unity only if every strategy sees the same numbers (the sampled direction
// leaves an offset origin, and for vertices 1e-2 apart in a corner that
// moved densities by 1 %, measured by bdpt_mis_check). The walk's steps
// follow pbrt-v4's RandomWalk (bdpt.cpp) with SmallVCM's light loop
// (vertexcm.hxx): every vertex is handed to `visit` as it is made.
// kMedia false compiles the walk for a scene without media (media must be
// null; the sampler then needs only next_1d and next_2d, as
// IndependentSampler's). Inlined into its caller, so that a sampler local
// there stays in registers.
template <bool kMedia = true, class S, class Visit>
[[gnu::always_inline]] inline void random_walk_with(const Scene& scene, S& sampler, Ray ray, Color beta,
                                                    TransportMode mode, int max_vertices, int rr_depth,
                                                    std::vector<PathVertex>& path, ThreadStats& stats, Visit& visit,
                                                    const MediumTracker* media, bool densities) {
    constexpr bool kWindow = WalksLastTwo<Visit>::value;
    if constexpr (kWindow) densities = false;  // the window keeps no vertex two back
    if constexpr (!kMedia) media = nullptr;
    BsdfContext ctx{mode};
    // Vertices made so far, the start included (path.size() outside the window mode).
    int count = int(path.size());
    if constexpr (kWindow) {
        count = 1;
        if (path.size() < 2) path.resize(2);
    }
    // The window's two slots (the buffer does not move during the walk):
    // `cur` holds the last vertex made, `other` the one before it.
    PathVertex* cur = kWindow ? path.data() : nullptr;
    PathVertex* other = kWindow ? cur + 1 : nullptr;
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
        const size_t n = size_t(count) - 1;  // index of v
        if constexpr (kWindow) {
            if (!visit(*cur, static_cast<const PathVertex*>(other), int(n))) return false;
            return count < max_vertices;
        }
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
        if constexpr (!kWindow) {
            if (!visit(path)) return false;
        }
        return count < max_vertices;
    };
    // A new vertex at the end of the walk (kFreshVertex, or a reset slot in
    // the window mode), and the one just made dropped.
    auto new_vertex = [&]() -> PathVertex& {
        ++count;
        if constexpr (kWindow) {
            std::swap(cur, other);
            reset_walk_slot(*cur);
            return *cur;
        } else {
            return path.emplace_back(kFreshVertex);
        }
    };
    auto drop_vertex = [&]() {
        --count;
        if constexpr (kWindow)
            std::swap(cur, other);
        else
            path.pop_back();
    };
    // Russian roulette after the depth-th scattering vertex (common.h):
    // Mitsuba's rule on the throughput since the start, volpath's in media.
    auto roulette = [&](int depth, float rr_u) {
        if (media)
            return survives_roulette(RouletteRule::BelowStart, depth, rr_depth,
                                     beta0 > 0.f ? max_component(th.beta) / beta0 * eta_scale : 0.f, rr_u, th.beta);
        float q = roulette_survival(RouletteRule::Capped, depth, rr_depth, max_component(thr) * eta_scale);
        if (!(rr_u < q)) return false;
        if (q < 1.f) {  // before rr_depth q is 1: nothing to divide
            th.beta /= q;
            thr /= q;
        }
        return true;
    };
    // depth: scattering vertices from the start to the new vertex (every
    // surface vertex without media; null boundaries excluded with them).
    // Every vertex is checked against max_vertices as it is added
    // (add_vertex), a dropped one lowers the count: only the start needs it here.
    if (count >= max_vertices) return;
    for (int depth = 1, guard = 0; guard < (1 << 20); ++guard) {
        // 1. The next surface along the ray, intersected straight into the
        //    vertex it may become (no Interaction copied per bounce); the
        //    slot is reset or dropped when it becomes another vertex or none.
        PathVertex& v = new_vertex();
        Interaction& it = v.it;
        ++stats.rays;
        bool hit = scene.intersect(ray, it);

        // 2. Free flight through the current medium (media_common.h); a
        //    scattering event is a Medium vertex, whose next direction the
        //    phase function samples (weight eval / pdf = 1 for ours).
        if constexpr (kMedia) {
            if (media && mt.medium >= 0) {
                const Medium& med = *scene.media[mt.medium];
                float t = 0.f;
                FlightEvent event = free_flight(med, ray, hit ? it.t : ray.tmax, sampler, th, t);
                if (event == kAbsorbed) {
                    drop_vertex();
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
                drop_vertex();
            }
            break;
        }
        const Shape& shape = *scene.shapes[it.shape];
        const Bsdf* bsdf = scene.bsdfs[shape.bsdf].get();

        // 4. Through media, an index-matched boundary is no vertex: cross it.
        if (media && bsdf->flags() == kNull) {
            mt.cross(it, ray.d, true);
            ray = it.spawn(ray.d);
            drop_vertex();
            continue;
        }

        // 5. A surface vertex.
        v.beta = th.beta;
        v.bsdf = bsdf;
        if constexpr (!kWindow) v.emitter = shape.emitter >= 0 ? scene.emitters[shape.emitter].get() : nullptr;
        v.medium = mt.medium;
        if (!add_vertex()) break;

        // 6. Sample the next direction (adjoint BSDF with the shading-normal
        //    correction in importance transport, common.h); the medium
        //    changes when the sample crosses a boundary.
        Vec3 wi = it.to_local(it.wi);
        ctx.set(it);
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

template <bool kMedia = true, class S, class Visit>
[[gnu::always_inline]] inline bool light_subpath_with(const Scene& scene, S& sampler, int max_vertices, int rr_depth,
                                                      std::vector<PathVertex>& light, EmissionSample& es,
                                                      ThreadStats& stats, Visit& visit, bool densities) {
    constexpr bool kWindow = WalksLastTwo<Visit>::value;
    if constexpr (!kWindow) light.clear();
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
    if constexpr (kWindow) {
        if (light.size() < 2) light.resize(2);
        reset_walk_slot(light[0]);
        light[0].beta = Color(0.f);
        light[0].bsdf = nullptr;
        light[0].medium = -1;
    }
    PathVertex& y0 = kWindow ? light[0] : light.emplace_back();
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
    if (kMedia && scene.features.has_media) {
        mt = emitter_medium(scene, ray, es.n, emitter_shape(scene, *e));
        y0.medium = mt.medium;
        y0.enclosed = mt.enclosed;
        if (y0.infinite) beta *= transmittance_from_infinity(scene, mt.medium);
    }
    if constexpr (kWindow) {
        if (!visit(y0, static_cast<const PathVertex*>(nullptr), 0)) return true;
    } else {
        if (!visit(light)) return true;
    }
    if (is_black(beta)) return true;  // y0 alone: light from infinity that no unbounded medium lets through
    // 4. The adjoint walk.
    random_walk_with<kMedia>(scene, sampler, ray, beta, TransportMode::Importance, max_vertices, rr_depth, light, stats,
                             visit, kMedia && scene.features.has_media ? &mt : nullptr, densities);
    return true;
}

}  // namespace rm
