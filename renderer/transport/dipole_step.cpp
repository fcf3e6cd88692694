// Exit-point sampling for the dipole BSSRDF, after pbrt-v3's
// SeparableBSSRDF::Sample_Sp / Pdf_Sp (PBR3 sec. 15.4), with J01's dipole
// profile sampled by exact inversion (Dipole::sample_r) instead of
// pbrt's tabulated one:
// 1. pick a colour channel (uniformly) and a probe axis of the entry
//    point's shading frame (the normal with probability 1/2, each tangent
//    with 1/4: most exit points lie near the tangent plane);
// 2. draw r from the channel's profile and an angle uniformly: a point on
//    the plane through xo orthogonal to the axis, at most r_max from xo;
// 3. a probe segment through that point along the axis, of half-length
//    sqrt(r_max^2 - r^2) (it stays in the sphere of radius r_max around
//    xo), collects every intersection with the same shape; one is chosen
//    uniformly;
// 4. its density is the one-sample MIS (balance heuristic) sum over the
//    3 axes x 3 channels that could have proposed it: each proposes the
//    point with its planar density at the point's distance from xo
//    projected on its plane, times |cos| between the point's normal and the
//    axis (the area-to-projected-area Jacobian); divided by the number of
//    hits on the chosen probe. The estimate Rd(|xi - xo|) / pdf is unbiased
//    for the part of the surface within r_max of xo (PBR3 sec. 15.4 and the
//    text around it).
#include "transport/dipole_step.h"

#include "scene/fresnel.h"

namespace rm {

namespace {
constexpr int kMaxProbeHits = 32;
constexpr float kAxisProb[3] = {0.25f, 0.25f, 0.5f};  // tangent s, tangent t, normal
}  // namespace

bool dipole_sample_exit(const Scene& scene, const Dipole& dp, const Interaction& xo, float u_ch, float u_axis,
                        Vec2 u_rphi, float u_sel, Interaction& xi, Color& weight, ThreadStats& stats) {
    int ch = std::min(int(u_ch * 3.f), 2);
    if (!dp.channel_ok(ch)) return false;
    const Frame& f = xo.sh;
    Vec3 axes[3] = {f.s, f.t, f.n};
    int a = u_axis < kAxisProb[2] ? 2 : (u_axis < kAxisProb[2] + kAxisProb[0] ? 0 : 1);
    Vec3 vz = axes[a], vx = axes[(a + 1) % 3], vy = axes[(a + 2) % 3];

    double r = dp.sample_r(ch, u_rphi.x), r_max = dp.r_max(ch);
    if (!(r >= 0.0) || !(r < r_max)) return false;
    float phi = 2.f * kPi * u_rphi.y;
    float half_l = float(std::sqrt(r_max * r_max - r * r));
    Vec3 base = xo.p + (vx * std::cos(phi) + vy * std::sin(phi)) * float(r) - vz * half_l;
    if (!is_finite(base) || !(half_l > 0.f) || !std::isfinite(2.f * half_l)) return false;

    // 3. Every intersection of the segment with xo's shape (others are passed through).
    Interaction hits[kMaxProbeHits];
    int n = 0;
    Ray ray{base, vz, 0.f, 2.f * half_l};
    for (int guard = 0; guard < 4 * kMaxProbeHits && n < kMaxProbeHits; ++guard) {
        Interaction h;
        ++stats.rays;
        if (!scene.intersect(ray, h)) break;
        if (h.shape == xo.shape) hits[n++] = h;
        float left = ray.tmax - h.t;
        if (!(left > 0.f)) break;
        Ray next = h.spawn(vz);
        next.tmax = left;
        ray = next;
    }
    if (n == 0) return false;
    xi = hits[std::min(int(u_sel * float(n)), n - 1)];

    // 4. Density of xi under all 9 axis-channel proposals.
    Vec3 d = xo.p - xi.p;
    Vec3 dl = f.to_local(d), nl = f.to_local(xi.n);
    double dist = length(d);
    double r_proj[3] = {std::sqrt(double(dl.y) * dl.y + double(dl.z) * dl.z),
                        std::sqrt(double(dl.z) * dl.z + double(dl.x) * dl.x),
                        std::sqrt(double(dl.x) * dl.x + double(dl.y) * dl.y)};
    double pdf = 0.0;
    for (int c = 0; c < 3; ++c) {
        // A channel's probes reach only the ball of radius r_max around xo
        // (the float rounding of the hit is allowed for).
        if (!dp.channel_ok(c) || dist > dp.r_max(c) * (1.0 + 1e-4)) continue;
        for (int k = 0; k < 3; ++k)
            pdf += (1.0 / 3.0) * kAxisProb[k] * dp.pdf_a(c, std::min(r_proj[k], dp.r_max(c))) * std::fabs(nl[k]);
    }
    pdf /= n;
    if (!(pdf > 0.0) || !std::isfinite(pdf)) return false;
    for (int c = 0; c < 3; ++c) weight[c] = float(dp.rd(c, dist) / pdf);
    if (!is_finite(weight) || !(weight.x >= 0.f && weight.y >= 0.f && weight.z >= 0.f)) return false;
    return true;
}

DipoleStep dipole_step(const Scene& scene, const Dipole& dp, Interaction& it, Sampler& sampler, ThreadStats& stats) {
    DipoleStep st;
    // Light from inside (a camera inside the object, an open mesh seen from
    // its back) is outside the model: the path ends.
    float cos_i = dot(it.wi, it.sh.n);
    if (!(cos_i > 0.f) || !(dot(it.wi, it.n) > 0.f)) return st;
    float fr = fresnel_dielectric(cos_i, dp.eta()).F;
    float u = sampler.next_1d();
    if (u < fr) {
        // Specular reflection of the smooth boundary, chosen with its own
        // probability Fr: weight Fr / Fr = 1.
        st.kind = DipoleStep::kReflected;
        BsdfSample& bs = st.reflection;
        bs.wo = reflect_local(it.to_local(it.wi));
        bs.weight = Color(1.f);
        bs.pdf_w = fr;
        bs.is_delta = true;
        bs.sampled_flags = kDeltaReflection;
        return st;
    }
    // The subsurface term Ft(wi) Rd Sw, chosen with probability Ft = 1 - Fr.
    float u_ch = sampler.next_1d(), u_axis = sampler.next_1d();
    Vec2 u_rphi = sampler.next_2d();
    float u_sel = sampler.next_1d();
    Interaction xi;
    Color w;
    if (!dipole_sample_exit(scene, dp, it, u_ch, u_axis, u_rphi, u_sel, xi, w, stats)) return st;
    xi.kind = VertexKind::Subsurface;
    xi.wi = xi.sh.n;
    it = xi;
    st.kind = DipoleStep::kSubsurface;
    st.weight = w;
    return st;
}

bool camera_dipole_vertex(const Scene& scene, const Dipole& dp, Interaction& it, Sampler& sampler, ThreadStats& stats,
                          Color& beta, PathClass& pc, const Bsdf*& bsdf, Vec3& wi, BsdfSample& bs, bool& sampled) {
    DipoleStep st = dipole_step(scene, dp, it, sampler, stats);
    if (st.kind == DipoleStep::kFailed) return false;
    if (st.kind == DipoleStep::kReflected) {
        bs = st.reflection;
        sampled = true;
    } else {
        beta *= st.weight;
        pc.subsurface = true;
        bsdf = &dp.exit_lobe();
        wi = Vec3(0.f, 0.f, 1.f);
    }
    return true;
}

}  // namespace rm
