// Media transport shared by volpath.cpp and subpath.cpp (media_common.h).
#include "transport/media_common.h"

namespace rm {

FlightEvent free_flight_homogeneous(const Medium& med, float t_hit, Sampler& sampler, SpectralThroughput& th,
                                    float& t) {
    int h = th.hero;
    float u_t = sampler.next_1d(), u_scatter = sampler.next_1d();
    float s = med.sigma_t[h];
    t = s > 0.f ? -std::log1p(-u_t) / s : kInf;
    if (t < t_hit) {
        if (!(u_scatter * med.sigma_t[h] < med.sigma_s[h])) return kAbsorbed;
        Color p = med.sigma_s * med.transmittance(t);
        return th.rescale(p / p[h]) ? kScattered : kAbsorbed;
    }
    Color tr = med.transmittance(t_hit);
    return tr[h] > 0.f && th.rescale(tr / tr[h]) ? kPassed : kAbsorbed;
}

FlightEvent free_flight_tracking(const Medium& med, const Ray& r, float t_hit, Sampler& sampler, SpectralThroughput& th,
                                 float& t) {
    int h = th.hero;
    const Color& maj = med.majorant;
    float m = maj[h];
    // Tracking runs over the ray's part inside the grid's box; outside it
    // the medium is vacuum (Medium::extent), so the flight passes there.
    float t_end;
    if (!med.extent(r.o, r.d, t_hit, t, t_end)) return kPassed;
    if (med.has_majorant_grid()) return free_flight_tracking_local(med, r, t, t_end, sampler, th, t);
    uint64_t lookups = 0;
    FlightEvent ev = kAbsorbed;
    for (int i = 0; i < (1 << 20); ++i) {
        float u_t = sampler.next_1d(), u_e = sampler.next_1d();
        float dt = m > 0.f ? -std::log1p(-u_t) / m : kInf;
        if (!(t + dt < t_end)) {
            Color tm = Medium::exp_neg(maj, t_end - t);
            ev = tm[h] > 0.f && th.rescale(tm / tm[h]) ? kPassed : kAbsorbed;
            break;
        }
        t += dt;
        Color st, ss;
        med.coefficients(r.o + r.d * t, st, ss);
        ++lookups;
        Color tm = Medium::exp_neg(maj, dt);
        float p_absorb = (st[h] - ss[h]) / m, p_scatter = ss[h] / m;
        if (u_e < p_absorb) break;  // kAbsorbed
        if (u_e < p_absorb + p_scatter) {
            Color p = ss * tm;
            ev = th.rescale(p / p[h]) ? kScattered : kAbsorbed;
            break;
        }
        Color p = (maj - st) * tm;
        if (!(p[h] > 0.f) || !th.rescale(p / p[h])) break;  // kAbsorbed
    }
    Medium::count_lookups(lookups);
    return ev;
}

// The same with local majorants (Medium::majorants): the flight crosses the
// cells of the majorant grid along [t, t_end] in order, each with its own
// majorant maj (per channel) and rate maj[hero]. The tentative-collision
// process of a piecewise-constant rate is sampled piecewise (exponential
// steps restarted at each cell border, memoryless), so its density is
// maj(t) exp(-int_0^t maj) with the local majorant, for the hero and, for
// the MIS bookkeeping, for every channel: as in free_flight_tracking, each
// event's per-channel density is its coefficient (sigma_s, or sigma_n =
// maj - sigma_t with the cell's maj) times the majorant transmittance Tm =
// exp(-tau) since the last tentative collision, tau the majorant's optical
// depth summed over the cells crossed. A cell where maj[hero] = 0 holds no
// medium for the hero (sigma_t <= maj): no collisions and no random
// numbers there, only its optical depth for the other channels.
FlightEvent free_flight_tracking_local(const Medium& med, const Ray& r, float t_start, float t_end, Sampler& sampler,
                                       SpectralThroughput& th, float& t) {
    const int h = th.hero;
    MajorantIterator cells = med.majorants(r.o, r.d, t_start, t_end);
    MajorantSegment seg;
    Color tau(0.f);  // the majorant's optical depth since the last tentative collision
    uint64_t lookups = 0;
    FlightEvent ev = kAbsorbed;
    int n = 0;
    while (cells.next(seg)) {
        const Color& maj = seg.maj;
        const float m = maj[h];
        float ts = seg.t0;  // where the optical depth not yet in tau starts
        if (m > 0.f) {
            for (;;) {
                if (++n > (1 << 20)) {
                    Medium::count_lookups(lookups);
                    return kAbsorbed;
                }
                float u_t = sampler.next_1d(), u_e = sampler.next_1d();
                float tc = ts + -std::log1p(-u_t) / m;
                if (!(tc < seg.t1)) break;
                t = tc;
                Color st, ss;
                med.coefficients(r.o + r.d * t, st, ss);
                ++lookups;
                // The cell's majorant bounds sigma_t up to float rounding
                // (Grid::build_majorants); the clamp keeps sigma_n >= 0.
                st = vmin(st, maj);
                ss = vmin(ss, st);
                tau += maj * (t - ts);
                ts = t;
                Color tm{std::exp(-tau.x), std::exp(-tau.y), std::exp(-tau.z)};
                tau = Color(0.f);
                float p_absorb = (st[h] - ss[h]) / m, p_scatter = ss[h] / m;
                if (u_e < p_absorb) {
                    Medium::count_lookups(lookups);
                    return kAbsorbed;
                }
                if (u_e < p_absorb + p_scatter) {
                    Color p = ss * tm;
                    ev = th.rescale(p / p[h]) ? kScattered : kAbsorbed;
                    Medium::count_lookups(lookups);
                    return ev;
                }
                Color p = (maj - st) * tm;
                if (!(p[h] > 0.f) || !th.rescale(p / p[h])) {
                    Medium::count_lookups(lookups);
                    return kAbsorbed;
                }
            }
        }
        tau += maj * (seg.t1 - ts);
    }
    Medium::count_lookups(lookups);
    t = t_end;
    Color tm{std::exp(-tau.x), std::exp(-tau.y), std::exp(-tau.z)};
    return tm[h] > 0.f && th.rescale(tm / tm[h]) ? kPassed : kAbsorbed;
}

Equiangular::Equiangular(const Vec3& o, const Vec3& d, float t_max_, const Vec3& y) : t_max(t_max_) {
    Vec3 v = y - o;
    delta = dot(v, d);
    dist = length(v - d * delta);
    if (!(dist > 0.f) || !std::isfinite(dist) || !(t_max >= 0.f)) return;
    theta_a = std::atan2(-delta, dist);
    // An infinite segment ends at pi / 2, taken as the float just below it
    // (float(pi / 2) lies above pi / 2, where tan turns negative).
    theta_b = std::isinf(t_max) ? std::nextafter(float(kPi / 2), 0.f) : std::atan2(t_max - delta, dist);
    ok = theta_b > theta_a;
}

float Equiangular::pdf(float t) const {
    if (!ok || !(t >= 0.f) || !(t <= t_max)) return 0.f;
    float h = t - delta;
    float p = dist / ((theta_b - theta_a) * (dist * dist + h * h));
    return std::isfinite(p) ? p : 0.f;
}

float Equiangular::sample(float u, float& p) const {
    p = 0.f;
    if (!ok) return 0.f;
    float theta = theta_a + u * (theta_b - theta_a);
    // Rounding may put t a hair outside the segment: it is kept inside.
    float t = std::min(std::max(delta + dist * std::tan(theta), 0.f), t_max);
    if (!std::isfinite(t)) return 0.f;
    p = pdf(t);
    return t;
}

float light_pdf_w_from(const Scene& scene, const Emitter& e, const LightContext& from, const Vec3& y, const Vec3& n,
                       const Vec3& x) {
    if (e.is_infinite()) return 0.f;
    float pick = emitter_pick_prob(scene, from, e);
    if (!(pick > 0.f)) return 0.f;
    if (e.is_delta()) return pick;
    float pdf_w = e.pdf_direct(from.p, y, n);
    if (!(pdf_w > 0.f)) return 0.f;
    Vec3 vo = y - from.p, vx = y - x;
    float do2 = length_sq(vo), dx2 = length_sq(vx);
    float cos_o = -dot(n, vo) / std::sqrt(do2), cos_x = -dot(n, vx) / std::sqrt(dx2);
    if (!(cos_o > 0.f) || !(cos_x > 0.f)) return 0.f;
    float p = pick * pdf_w * (cos_o / do2) * (dx2 / cos_x);  // Veach 1997, eq. 8.10, twice
    return std::isfinite(p) ? p : 0.f;
}

MediumTracker emitter_medium(const Scene& scene, const Ray& ray, const Vec3& n, int it_shape) {
    // Inside shape `s` (the side against its normal) behind a non-null BSDF:
    // a subsurface medium (MediumTracker::cross's rule).
    auto enclosed_in = [&](const Shape& s, int medium) {
        return medium >= 0 && medium == s.medium_interior && s.bsdf >= 0 && scene.bsdfs[s.bsdf]->flags() != kNull;
    };
    MediumTracker mt;
    if (it_shape >= 0) {
        const Shape& s = *scene.shapes[it_shape];
        if (s.medium_interior >= 0 || s.medium_exterior >= 0) {
            mt.medium = dot(ray.d, n) > 0.f ? s.medium_exterior : s.medium_interior;
            mt.enclosed = dot(ray.d, n) <= 0.f && enclosed_in(s, mt.medium);
            return mt;
        }
    }
    Ray r = ray;
    // Each step passes one surface that declares no medium (a bound keeps a
    // ray caught between coincident surfaces from looping).
    for (int step = 0; step < 1024; ++step) {
        Interaction it;
        if (!scene.intersect(r, it)) break;
        if (it.medium_inside >= 0 || it.medium_outside >= 0) {
            mt.medium = Scene::medium_after(it, -r.d, -1);
            mt.enclosed = dot(r.d, it.n) > 0.f && enclosed_in(*scene.shapes[it.shape], mt.medium);
            return mt;
        }
        r = it.spawn(r.d);
    }
    mt.medium = scene.sensor_desc.medium;  // not enclosed: as the camera's own paths start (volpath)
    return mt;
}

Color transmittance_from_infinity(const Scene& scene, int medium) {
    if (medium < 0) return Color(1.f);
    const Medium& m = *scene.media[medium];
    if (!m.homogeneous) return Color(1.f);
    return {m.sigma_t.x > 0.f ? 0.f : 1.f, m.sigma_t.y > 0.f ? 0.f : 1.f, m.sigma_t.z > 0.f ? 0.f : 1.f};
}

}  // namespace rm
