// `volpath`: path tracing with participating media, the camera-ray loop that
// `path` (and its alias `volpath`) runs when the scene has media
// (Scene::features.has_media); scenes without media never enter this file.
// Parameters are `path`'s (max_depth, rr_depth, hide_emitters; and
// equiangular, step 5 below), with
// Mitsuba 3 volpath's meaning: a medium scattering event and a surface
// scattering event each count as one vertex towards max_depth;
// index-matched (null BSDF) boundaries are not vertices and do not count,
// nor is a thindielectric's straight-through sample (its kNull lobe): as in
// Mitsuba 3's volpath (src/integrators/volpath.cpp, non_null_bsdf) it is a
// null event that leaves depth, the MIS reference vertex and the path's
// class alone, and shadow rays pass such a surface with its
// null_transmission (Scene::transmittance). bdpt and ptracer keep it a
// vertex, each consistently within itself.
//
// The estimator, after the seed and pbrt-v4's VolPathIntegrator::Li:
// 1. Free flight: in a medium, a distance t is sampled with density
//    sigma_t exp(-sigma_t t) (mean free path 1 / sigma_t), with the
//    extinction of the path's hero channel, drawn uniformly once per path
//    (hero wavelength sampling, Wilkie et al. 2014).
// 2. At a sampled point the path scatters with probability sigma_s/sigma_t
//    (the hero's), else it is absorbed: the seed's analog walk, whose weight
//    stays exactly 1 in a grey medium. For RGB-varying media the three
//    channels are combined by spectral MIS over the whole path: the path's
//    density under each channel's sampling is tracked (r_u) and the estimate
//    is f / mean_c p_c, the one-sample balance heuristic over channels
//    (Miller, Georgiev and Jarosz 2019, "A null-scattering path integral
//    formulation of light transport", sec. 5.2; pbrt-v4's
//    VolPathIntegrator, PBR4 sec. 14.2.2). Its weight is at most 3 times the
//    hero's, however long the walk; a per-event average instead multiplies
//    bounded factors into an exponentially growing weight
//    (docs/measurements.md).
//    Heterogeneous (grid) media: delta tracking with null collisions against
//    a majorant, the same per-channel bookkeeping (see free_flight_tracking).
// 3. Next event estimation from every scattering vertex (surface or medium)
//    with the transmittance of the shadow ray through media and null
//    boundaries (Scene::transmittance: Beer-Lambert, or ratio tracking in
//    grid media), combined with BSDF /
//    phase-function sampling by the power heuristic (Veach 1997, eq. 9.13).
//    An emitter hit after crossing null boundaries is weighted against the
//    light sample from the last scattering vertex.
// 4. Medium tracking: the current medium changes only at shapes that declare
//    an interior or exterior medium (Mitsuba 3's rule: target_medium(d) is
//    the exterior when d . n > 0, else the interior); the camera starts in
//    the sensor's medium.
// 5. `equiangular` (default false; off, nothing here draws or computes):
//    each segment of the path through a homogeneous medium, [0, t_max] from
//    where it starts (o) to the next surface (infinite in an open medium),
//    also gets one equiangular sample (Kulla and Fajardo 2012, sec. 4;
//    media_common.h's Equiangular): a light point y picked and sampled from
//    o as NEE does (pick_emitter and sample_direct from o's medium context,
//    whatever o itself receives from y), t drawn with the
//    equiangular density p_eq(t) about y, and the light y sends through a
//    scattering at x = o + t d:
//        beta_o sigma_s Tr(t) phase(wi, wo) Tr(x, y) Le / (p_eq(t) q_o),
//    beta_o the throughput where the segment starts, q_o y's density
//    in solid angle at x (light_pdf_w_from: the pick from o alone for a
//    point or spot light). It removes the 1 / |x - y|^2 of single
//    scattering near a point-like light, which free flight samples badly
//    (free flight puts vertices where the medium is, not where the light is).
//    MIS: the same scattering at t towards y is also made by free flight
//    followed by NEE from x, of density (per the prefix's) b =
//    mean_c(r_u_c sigma_s_c Tr_c(t)) q_x, q_x = the light sample's pick times
//    pdf_w from x, where equiangular gives a = p_eq(t) q_o; the two get the
//    power heuristic's W_eq = a^2 / (a^2 + b^2) and W_ff = 1 - W_eq (Veach
//    1997, eq. 9.13). The mean over channels with the prefix's normalised
//    r_u is the spectral MIS of step 2 carried through (the one-sample
//    balance heuristic over channels nested in the two-strategy weights:
//    each strategy's estimate is W_s f / mean_c p_c,s, and with W_eq + W_ff
//    = 1 for every (t, y) the sum over strategies and channels is 1; the
//    equiangular estimate does not depend on the hero, so it takes beta_o
//    as it is). For area lights free flight also reaches y by phase
//    sampling (step 3's weights w_nee + w_phase = 1): the phase-sampled
//    emission keeps w_phase, and the split is of NEE's share only, W_ff w_nee
//    and W_eq w_nee (w_nee computed at x for the equiangular sample), which
//    again sums to 1. Where equiangular cannot make y from o (an emitter at
//    infinity, a light point facing away from o, a pick of 0 from o) a = 0
//    and free flight keeps it all. The equiangular vertex is a medium
//    vertex (V, or B behind a dielectric boundary) at depth + 1, classified,
//    masked and cut by max_depth as step 3's free-flight vertex is. Its five random numbers are drawn after
//    every other draw of the bounce (at the top of the next loop iteration
//    or after the loop), so the bounce's own dimensions keep their place.
//    Grid media keep free flight alone (documented; res.stats'
//    equiangular_samples counts the equiangular samples made, and the
//    Python facade warns when a render asked for them and made none).
#include "estimators/volpath.h"
#include "transport/common.h"
#include "transport/dipole_step.h"
#include "transport/media_common.h"
#include "transport/scatter_origin.h"

namespace rm {

namespace {

// The medium vertex at distance t along the ray (o, d).
Interaction medium_vertex(const Vec3& o, const Vec3& d, float t) {
    Interaction mi;
    mi.kind = VertexKind::Medium;
    mi.valid = true;
    mi.p = o + d * t;
    mi.wi = -d;
    mi.t = t;
    return mi;
}

// A segment of the path through a homogeneous medium awaiting its
// equiangular sample (step 5 of the head comment), with the path's state
// where it starts.
struct EquiSegment {
    bool active = false;
    Vec3 o, d;
    float t_max = 0.f;
    const Medium* med = nullptr;
    int medium = -1;
    Color beta, r_u;      // throughput and normalised channel densities at o
    int cls = 0;          // the class of light scattered on the segment
    bool wanted = false;  // the mask keeps that class
};

// Free flight's density of scattering at t on `seg` (per the prefix's,
// averaged over the channels: step 5).
float free_flight_density(const EquiSegment& seg, float t) {
    return average(seg.r_u * seg.med->sigma_s * seg.med->transmittance(t));
}

// W_ff for the NEE sample ds (on emitter e) from the free-flight vertex at t.
float free_flight_weight(const Scene& scene, const EquiSegment& seg, float t, const Emitter& e,
                         const DirectSample& ds) {
    Vec3 x = seg.o + seg.d * t;
    float q_o = light_pdf_w_from(scene, e, LightContext{seg.o, Vec3(0.f)}, ds.p, ds.n, x);
    float a = q_o > 0.f ? Equiangular(seg.o, seg.d, seg.t_max, ds.p).pdf(t) * q_o : 0.f;
    if (!(a > 0.f)) return 1.f;
    return mis_power(free_flight_density(seg, t) * ds.pdf_w * ds.pick, a);
}

// The equiangular sample of `seg` (step 5); always draws five numbers.
void sample_equiangular(const Scene& scene, Sampler& sampler, EquiSegment& seg, EffectRadiance& out,
                        ThreadStats& stats) {
    seg.active = false;
    float u_pick = sampler.next_1d();
    Vec2 u = sampler.next_2d();
    float u_extra = sampler.next_1d(), u_t = sampler.next_1d();
    if (!seg.wanted) return;
    // The light point y, picked and sampled from the segment's start as
    // NEE does, though what o itself receives from it does not matter
    // (a spot light outside its cone from o still lights the segment).
    const LightContext from{seg.o, Vec3(0.f)};
    float pick = 0.f;
    const Emitter* e = pick_emitter(scene, from, u_pick, pick);
    if (!e || e->is_infinite()) return;
    DirectSample ds_o = e->sample_direct(seg.o, u, u_extra);
    if (!(ds_o.pdf_w > 0.f)) return;
    const Equiangular eq(seg.o, seg.d, seg.t_max, ds_o.p);
    float pdf_t = 0.f;
    float t = eq.sample(u_t, pdf_t);
    if (!(pdf_t > 0.f)) return;
    ++stats.equiangular_samples;
    const Interaction mi = medium_vertex(seg.o, seg.d, t);
    float q_o = light_pdf_w_from(scene, *e, from, ds_o.p, ds_o.n, mi.p);
    if (!(q_o > 0.f)) return;
    // y seen from x, as light sampling from x would have made it.
    DirectSample ds;
    if (e->is_delta()) {
        ds = e->sample_direct(mi.p, Vec2(0.f, 0.f), 0.f);  // a delta position: the same point
        if (!ds.is_delta || is_black(ds.radiance)) return;
    } else {
        Vec3 v = ds_o.p - mi.p;
        ds.dist = length(v);
        if (!(ds.dist > 0.f)) return;
        ds.p = ds_o.p;
        ds.n = ds_o.n;
        ds.eps = ds_o.eps;
        ds.d = v / ds.dist;
        ds.pdf_w = e->pdf_direct(mi.p, ds.p, ds.n);
        ds.radiance = ds_o.radiance;  // Le at y (light_pdf_w_from checked that y faces x)
    }
    ds.pick = emitter_pick_prob(scene, light_context(mi), *e);
    const PhaseFunction& phase = *seg.med->phase;
    float f = phase.eval(mi.wi, ds.d);
    if (!(f > 0.f)) return;
    float q_x = ds.pdf_w * ds.pick;
    float w_nee = ds.is_delta ? 1.f : mis_power(q_x, phase.pdf_w(mi.wi, ds.d));
    float w = w_nee * mis_power(pdf_t * q_o, free_flight_density(seg, t) * q_x);
    if (!(w > 0.f)) return;
    ++stats.shadow_rays;
    Color tr = scene.transmittance(mi, ds, seg.medium, stats.rays, sampler, true);
    if (is_black(tr)) return;
    Color scatter = seg.med->sigma_s * seg.med->transmittance(t);
    out.add(seg.cls, seg.beta * scatter * tr * ds.radiance * (f * w / (pdf_t * q_o)));
}

}  // namespace

void volpath_sample(const Scene& scene, Sampler& sampler, const Ray& camera_ray, EffectRadiance& out,
                    ThreadStats& stats, const VolPathParams& prm, const EffectMask& mask) {
    // The camera ray starts at its near-clip point (as Mitsuba's cameras do),
    // so the medium is sampled from there.
    Ray ray = camera_ray;
    ray.o = ray.o + ray.d * ray.tmin;
    ray.tmax = std::isinf(ray.tmax) ? kInf : ray.tmax - ray.tmin;
    ray.tmin = 0.f;
    MediumTracker mt{scene.sensor_desc.medium, false};  // B vertices: behind a non-null boundary
    int& medium = mt.medium;
    float eta_scale = 1.f;
    PathClass pc;
    float prev_pdf_w = 0.f;
    bool prev_delta = true;
    ScatterOrigin prev;  // the vertex the current ray left (scatter_origin.h)
    LightContext prev_ctx{};
    BsdfContext ctx;
    int depth = 0;  // scattering vertices so far (surface or medium; null boundaries excluded)
    SpectralThroughput th(std::min(int(sampler.next_1d() * 3.f), 2));
    Color& beta = th.beta;
    // Russian roulette only once the throughput has fallen below 1 (pbrt-v4's
    // rule, not Mitsuba's of the surface loop: common.h says why).
    auto roulette = [&](float rr_u) {
        return survives_roulette(RouletteRule::BelowStart, depth, prm.rr_depth, max_component(beta) * eta_scale, rr_u,
                                 beta);
    };
    EquiSegment seg;  // step 5 (`equiangular`)
    for (int guard = 0; guard < (1 << 20); ++guard) {
        // 0. The last segment's equiangular sample, after the bounce's other draws.
        if (seg.active) sample_equiangular(scene, sampler, seg, out, stats);
        // 1. Find the next surface along the ray.
        Interaction it;
        ++stats.rays;
        bool hit = scene.intersect(ray, it);
        float t_hit = hit ? it.t : ray.tmax;
        bool count_emission = !(depth == 0 && prm.hide);

        // 2. Free flight through the current medium, with the hero channel's
        //    extinction; r_u tracks every channel's path density over the hero's.
        if (medium >= 0) {
            const Medium& med = *scene.media[medium];
            // 2a. A segment through a homogeneous medium: its equiangular
            //     sample comes at step 0 (head comment, step 5).
            if (prm.equiangular && med.homogeneous && !scene.emitters.empty() &&
                (prm.max_depth < 0 || depth + 1 < prm.max_depth)) {
                PathClass pn = pc;
                pn.push_medium(mt.enclosed);
                seg.active = true;
                seg.o = ray.o;
                seg.d = ray.d;
                seg.t_max = t_hit;
                seg.med = &med;
                seg.medium = medium;
                seg.beta = beta;
                seg.r_u = th.r_u;
                seg.cls = pn.classify();
                seg.wanted = mask[seg.cls];
            }
            float t = 0.f;
            FlightEvent event = free_flight(med, ray, t_hit, sampler, th, t);
            if (event == kAbsorbed) break;
            if (event == kScattered) {
                ++depth;
                if (prm.max_depth >= 0 && depth >= prm.max_depth) break;
                const Interaction mi = medium_vertex(ray.o, ray.d, t);
                const PhaseFunction& phase = *med.phase;
                PathClass pn = pc;
                pn.push_medium(mt.enclosed);
                int ncls = pn.classify();
                // 3. Next event estimation from the medium vertex.
                if (!scene.emitters.empty()) {
                    if (mask[ncls]) {
                        auto f_of = [&](const Vec3& wo) { return Color(phase.eval(mi.wi, wo)); };
                        auto pdf_of = [&](const Vec3& wo) { return phase.pdf_w(mi.wi, wo); };
                        Color ld;
                        if (seg.active) {  // an equiangular sample on this segment: W_ff (step 5)
                            auto w_ff = [&](const Emitter& e, const DirectSample& ds) {
                                return free_flight_weight(scene, seg, t, e, ds);
                            };
                            ld = direct_through_media(scene, mi, medium, sampler, stats, f_of, pdf_of, true, w_ff);
                        } else {
                            ld = direct_through_media(scene, mi, medium, sampler, stats, f_of, pdf_of, true);
                        }
                        out.add(ncls, beta * ld);
                    } else {
                        sampler.next_1d();
                        sampler.next_2d();
                        sampler.next_1d();
                    }
                }
                pc = pn;
                // 4. Phase-function sampling for the next direction.
                PhaseSample ps = phase.sample(mi.wi, sampler.next_2d());
                if (!(ps.pdf_w > 0.f)) break;
                beta *= ps.weight;
                prev_pdf_w = ps.pdf_w;
                prev_delta = false;
                prev.p = mi.p;  // a medium vertex: the ray leaves mi.p itself
                prev.bsdf = nullptr;
                prev_ctx = light_context(mi);
                ray = Ray{mi.p, ps.wo, 0.f, kInf};
                if (!roulette(sampler.next_1d())) break;
                if (!pc.can_reach(mask, true)) break;
                continue;
            }
        }
        int cls = pc.classify();

        // 5. Emission reached by the previous BSDF / phase sample (or the camera ray).
        if (count_emission && mask[cls]) {
            float pdf_w = prev_pdf_w;
            if (hit && !prev_delta && scene.shapes[it.shape]->emitter >= 0) pdf_w = prev.pdf_to(it.p, prev_pdf_w);
            add_emission_at_hit(scene, ray, hit ? &it : nullptr, beta, cls, depth, prev_delta, prev_ctx, prev.p, pdf_w,
                                out);
        }
        if (!hit) break;
        const Shape& shape = *scene.shapes[it.shape];
        const Bsdf& bsdf = *scene.bsdfs[shape.bsdf];

        // 6. An index-matched boundary: cross it, change medium, keep the path state.
        if (bsdf.flags() == kNull) {
            mt.cross(it, ray.d, true);
            ray = it.spawn(ray.d);
            continue;
        }
        Vec3 wi = it.to_local(it.wi);
        ctx.set(it);
        const Bsdf* bsdf_at = &bsdf;
        BsdfSample bs;
        bool sampled = false;

        // 6b. A BSDF with a null lobe (thindielectric) is sampled first: its
        //     straight-through sample is a null event, as at 6 but weighted;
        //     any other sample is this vertex's (no NEE: no smooth lobe).
        if ((bsdf.flags() & kNull) && shape.dipole < 0) {
            bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
            if (bs.sampled_flags == kNull) {
                if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) break;
                beta *= bs.weight;
                mt.cross(it, ray.d, true);
                ray = it.spawn(ray.d);
                continue;
            }
            sampled = true;
        }

        // 7. Stop at max_depth, or when no requested class is reachable.
        if (prm.max_depth >= 0 && depth + 1 >= prm.max_depth) break;
        if (!pc.can_reach(mask, true)) break;

        // 7a. A dipole BSSRDF (dipole_step.h), as in path.cpp: specular
        //     reflection, or the exit point xi (a B vertex) with the exit
        //     lobe as its BSDF. The path never enters the object, so the
        //     current medium (outside it) stays.
        if (shape.dipole >= 0 && !camera_dipole_vertex(scene, *scene.dipoles[shape.dipole], it, sampler, stats, beta,
                                                       pc, bsdf_at, wi, bs, sampled))
            break;

        if (!sampled) {
            // 8. Next event estimation at the surface, through media.
            if (bsdf_at->has_smooth() && !scene.emitters.empty()) {
                PathClass pn = pc;
                pn.push(false);
                int ncls = pn.classify();
                if (mask[ncls]) {
                    Color ld = direct_through_media(
                        scene, it, medium, sampler, stats,
                        [&](const Vec3& wo) { return bsdf_at->eval(ctx, wi, it.to_local(wo)); },
                        [&](const Vec3& wo) { return bsdf_at->pdf_w(ctx, wi, it.to_local(wo)); }, true);
                    out.add(ncls, beta * ld);
                } else {
                    sampler.next_1d();
                    sampler.next_2d();
                    sampler.next_1d();
                }
            }
            // 9. BSDF sampling; the medium changes when the sample crosses a boundary.
            bs = bsdf_at->sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
        }
        if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) break;
        beta *= bs.weight;
        eta_scale *= sqr(bs.eta);
        pc.push(bs.is_delta);
        ++depth;
        prev_pdf_w = bs.pdf_w;
        prev_delta = bs.is_delta;
        Vec3 wo = it.to_world(bs.wo);
        mt.cross(it, wo, false);
        prev.set(it, wi, bsdf_at);
        ray = it.spawn(wo);
        prev_ctx = light_context(it);
        if (!roulette(sampler.next_1d())) break;
    }
    if (seg.active) sample_equiangular(scene, sampler, seg, out, stats);
}

namespace {

class VolPathIntegrator final : public Integrator {
public:
    explicit VolPathIntegrator(const VolPathParams& prm) : prm_(prm) {}
    void sample(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out,
                ThreadStats& stats) const override {
        volpath_sample(scene, sampler, ray, out, stats, prm_, mask);
    }

private:
    VolPathParams prm_;
};

}  // namespace

std::unique_ptr<Integrator> make_volpath_integrator(const VolPathParams& prm) {
    return std::make_unique<VolPathIntegrator>(prm);
}

}  // namespace rm
