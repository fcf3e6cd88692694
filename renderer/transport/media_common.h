// Pieces of media transport shared by the camera-path loop (volpath.cpp),
// the subpaths of ptracer and bdpt (subpath.cpp) and photon tracing
// (photon_trace.cpp): the spectral-MIS path
// throughput, the two free-flight samplers, medium tracking across
// boundaries and the medium an emitter's light starts in; and light
// sampling through media (volpath.cpp, photonmapper.cpp).
#pragma once
#include <cstddef>
#include <type_traits>

#include "transport/common.h"

namespace rm {

// Path throughput under spectral MIS (hero channel): one channel, drawn
// uniformly per path, drives every free-flight distance and
// scatter/absorb choice; r_u holds each channel's path density divided by the
// hero's. The estimate is f / mean_c p_c = (f / p_hero) / mean(r_u), the
// one-sample balance heuristic over the three channels' samplers (Miller,
// Georgiev and Jarosz 2019, sec. 5.2; PBR4 sec. 14.2.2); both are rescaled
// after each update so that mean(r_u) = 1 and `beta` is the estimate itself
// (no overflow however long the walk). The medium events are symmetric in
// the direction of transport, so a light subpath (importance transport)
// uses the same bookkeeping: its beta becomes f / mean_c p_c of its prefix.
struct SpectralThroughput {
    explicit SpectralThroughput(int h, const Color& b = Color(1.f)) : hero(h), beta(b) {}
    int hero;
    Color beta{1.f}, r_u{1.f};
    // `ratio`: an event's contribution over the hero's density, which for
    // every medium event here equals its per-channel density over the hero's.
    bool rescale(const Color& ratio) {
        r_u *= ratio;
        beta *= ratio;
        float m = average(r_u);
        if (!(m > 0.f) || !std::isfinite(m)) return false;
        r_u /= m;
        beta /= m;
        return true;
    }
};

// Free flight through a medium up to the next surface at t_hit, with the
// hero channel's extinction; `t` receives the scattering distance.
enum FlightEvent { kPassed, kScattered, kAbsorbed };

// Homogeneous: free-flight distance of density sigma_t exp(-sigma_t t)
// (mean 1 / sigma_t); at a collision, scatter with probability
// sigma_s / sigma_t of the hero, else absorb (the seed). Density of
// collide-and-scatter per channel: sigma_s Tr(t); of passing: Tr(t_hit).
FlightEvent free_flight_homogeneous(const Medium& med, float t_hit, Sampler& sampler, SpectralThroughput& th, float& t);

// Heterogeneous: delta tracking with null collisions against the majorant
// (Woodcock et al. 1965; the null-scattering path integral of Miller et al.
// 2019, sec. 4; Novak et al. 2018, sec. 4): tentative collisions at rate
// majorant[hero]; absorb, scatter or pass on (null) with probabilities
// sigma_a, sigma_s and sigma_n = majorant - sigma_t over the majorant (the
// hero's). Per-channel densities: sigma_s Tm, sigma_n Tm (Tm the majorant's
// transmittance). A medium with a majorant grid (Medium::has_majorant_grid)
// goes to free_flight_tracking_local: the same with the cells' majorants.
FlightEvent free_flight_tracking(const Medium& med, const Ray& r, float t_hit, Sampler& sampler, SpectralThroughput& th,
                                 float& t);
// The same over [t_start, t_end] (the medium's extent) with the local
// majorants of the medium's majorant grid (Medium::has_majorant_grid).
FlightEvent free_flight_tracking_local(const Medium& med, const Ray& r, float t_start, float t_end, Sampler& sampler,
                                       SpectralThroughput& th, float& t);

// Either of the two above, for the medium's kind.
inline FlightEvent free_flight(const Medium& med, const Ray& r, float t_hit, Sampler& sampler, SpectralThroughput& th,
                               float& t) {
    return med.homogeneous ? free_flight_homogeneous(med, t_hit, sampler, th, t)
                           : free_flight_tracking(med, r, t_hit, sampler, th, t);
}

// The current medium of a path and whether it is a shape's interior entered
// through a non-null (dielectric) boundary, i.e. whether a scattering event
// there is a subsurface vertex B rather than a volume vertex V (PathClass).
// Mitsuba 3's rule: the medium changes only at shapes that declare an
// interior or exterior medium (Scene::medium_after).
struct MediumTracker {
    int medium = -1;
    bool enclosed = false;
    // The path leaves surface `it` in direction wo; `null_bsdf`: an
    // index-matched boundary, crossing which never encloses.
    void cross(const Interaction& it, const Vec3& wo, bool null_bsdf) {
        int next = Scene::medium_after(it, wo, medium);
        if (next != medium) enclosed = !null_bsdf && next >= 0 && next == it.medium_inside && dot(wo, it.n) < 0.f;
        medium = next;
    }
};

// The medium a light ray leaving an emitter at `ray.o` travels in: for an
// area emitter on a shape that declares media (`it_shape`, its shape index;
// -1 otherwise) the side the ray leaves to; else the medium on the near
// side of the first medium boundary along the ray (the medium only changes
// at such boundaries), and the sensor's medium when there is none (the
// region connected to infinity is taken to be the camera's, the one
// assumption of this rule; a camera enclosed by a medium boundary with a
// light outside it would break it).
//
// Returned as a MediumTracker: `enclosed` is set when that medium is the
// interior of a non-null (dielectric) boundary, so that light paths
// starting there file their medium vertices as subsurface (B), as a camera
// path that entered through the boundary does.
MediumTracker emitter_medium(const Scene& scene, const Ray& ray, const Vec3& n, int it_shape);

// The transmittance from infinity to where an emitter at infinity's light
// ray starts (the disk outside the scene) in medium `medium`: light from
// infinity through an unbounded homogeneous medium arrives only in
// channels with sigma_t = 0 (volpath's and Mitsuba's shadow rays towards it
// see exp(-sigma_t inf)); grid media are vacuum outside their box, so 1.
Color transmittance_from_infinity(const Scene& scene, int medium);

// Equiangular distance sampling (Kulla and Fajardo 2012, "Importance
// Sampling Techniques for Path Tracing in Participating Media", sec. 4.1),
// volpath's `equiangular` option (volpath.cpp's head says how it is
// combined with free flight). Along the segment o + t d, t in [0, t_max]
// (t_max may be infinite), towards a light point y: with delta = (y - o).d
// the foot of the perpendicular and D = |y - o - delta d| the point's
// distance from the ray's line, t = delta + D tan(theta), theta uniform in
// [theta_a, theta_b] = [atan(-delta / D), atan((t_max - delta) / D)]
// (theta_b = pi / 2 for an infinite segment), of density
//     p(t) = D / ((theta_b - theta_a) (D^2 + (t - delta)^2))
// (their eq. 4 and the inversion after it), which cancels the 1 / |x - y|^2
// of the light's geometry term exactly. Degenerate (D = 0: y on the line;
// theta_b = theta_a: a segment of length 0): `ok` false, the density 0
// everywhere (the segment is left to free flight).
struct Equiangular {
    Equiangular(const Vec3& o, const Vec3& d, float t_max, const Vec3& y);
    bool ok = false;
    float delta = 0.f, dist = 0.f, theta_a = 0.f, theta_b = 0.f;
    // t for u in [0, 1); its density in `pdf` (0: no sample).
    float sample(float u, float& pdf) const;
    // The density of t (0 outside [0, t_max] or when not ok).
    float pdf(float t) const;
    float t_max = 0.f;
};

// The solid-angle density, seen from x, with which light sampling from
// `from` (a medium point's context, pick included) produces the point y
// (normal n) of emitter e: for an area emitter pick * pdf_direct(from, y)
// converted to area at y and back to solid angle at x (Veach 1997, eq.
// 8.10); for a delta position (point, spot, projector) the pick alone (the
// point is the same from everywhere); 0 for emitters at infinity and where
// y is not reachable from `from` or does not face x.
float light_pdf_w_from(const Scene& scene, const Emitter& e, const LightContext& from, const Vec3& y, const Vec3& n,
                       const Vec3& x);

// NEE at a scattering vertex `it` (surface or medium) through media and
// index-matched boundaries: `f_of(wo)` is the BSDF value (times cosine) or
// the phase function, `pdf_of(wo)` the density of the direction sampling
// it competes with, weighted by the power heuristic (Veach 1997, eq. 9.13).
// pdf_of = nullptr: light samples only, no MIS weight (photonmapper, where
// nothing else finds the emitters from `it`). through_null_lobes: shadow
// rays pass thindielectric surfaces (volpath's null events, Scene::transmittance).
// `weight_of(e, ds)`, when given, multiplies the contribution of the light
// sample ds on emitter e by a further weight (volpath's equiangular MIS).
template <typename EvalF, typename PdfF, typename WeightF = std::nullptr_t>
Color direct_through_media(const Scene& scene, const Interaction& it, int medium, Sampler& sampler, ThreadStats& stats,
                           EvalF f_of, PdfF pdf_of, bool through_null_lobes = false, WeightF weight_of = nullptr) {
    DirectSample ds;
    const Emitter* e = nullptr;
    if (!sample_light(scene, light_context(it), sampler, ds, &e)) return Color(0.f);
    Color f = f_of(ds.d);
    if (is_black(f)) return Color(0.f);
    ++stats.shadow_rays;
    int m = it.kind == VertexKind::Medium ? medium : Scene::medium_after(it, ds.d, medium);
    Color tr = scene.transmittance(it, ds, m, stats.rays, sampler, through_null_lobes);
    if (is_black(tr)) return Color(0.f);
    float light_pdf = ds.pdf_w * ds.pick;
    float w = 1.f;
    if constexpr (!std::is_same_v<PdfF, std::nullptr_t>)
        if (!ds.is_delta) w = mis_power(light_pdf, pdf_of(ds.d));
    if constexpr (!std::is_same_v<WeightF, std::nullptr_t>) w *= weight_of(*e, ds);
    return f * tr * ds.radiance * (w / light_pdf);
}

}  // namespace rm
