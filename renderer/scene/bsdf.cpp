// The BSDF plugins, with Mitsuba 3's names, parameters and semantics (the
// suite compares our images with Mitsuba's per pixel). All directions are in
// the local shading frame, pointing away from the surface; eval() includes
// |cos theta_o|; a sample's weight is eval / pdf_w, or for a delta lobe its
// Fresnel/albedo factor over the lobe's selection probability (pdf_w).
//
// Parameters (BsdfDesc fields; the Python loader resolves Mitsuba's defaults
// and named IORs, so e.g. plastic's default int_ior, polypropylene = 1.49,
// arrives here already filled in):
//  diffuse          reflectance. One-sided: 0 unless wi.z > 0 and wo.z > 0.
//  conductor        eta, k (complex IOR relative to the exterior; (0, 1) is
//                   Mitsuba's material "none", a perfect mirror, F = 1),
//                   specular_reflectance. One-sided (wi.z > 0).
//  roughconductor   as conductor + distribution (beckmann | ggx), alpha_u,
//                   alpha_v, sample_visible. One-sided.
//  dielectric       int_ior, ext_ior, specular_reflectance,
//                   specular_transmittance. Two-sided: wi.z < 0 is inside.
//  roughdielectric  as dielectric + distribution, alpha_u, alpha_v,
//                   sample_visible. Two-sided. int_ior == ext_ior is rejected
//                   (as Mitsuba does): the transmission lobe would be a delta.
//  thindielectric   int_ior, ext_ior, specular_reflectance,
//                   specular_transmittance. Two-sided; transmission goes straight
//                   through and is flagged kNull, as in Mitsuba.
//  plastic          int_ior, ext_ior, diffuse_reflectance, specular_reflectance,
//                   nonlinear. One-sided smooth coating over a diffuse base.
//  roughplastic     as plastic + distribution, alpha (alpha_u == alpha_v: only
//                   isotropic roughness, as Mitsuba), sample_visible. One-sided
//                   rough coating over a diffuse base; int_ior == ext_ior is
//                   rejected (as Mitsuba).
//  twosided         nested: 1 BSDF used on both sides, or 2 (front, back). The
//                   nested BSDFs must not transmit (as Mitsuba).
//  null             none. Passes light unchanged (medium boundaries).
//  blendbsdf        weight (floats["weight"], no default, as Mitsuba 3.9.1;
//                   clamped to [0, 1] where read), nested: 2 BSDFs;
//                   (1 - weight) f_0 + weight f_1. A textured weight with a
//                   nested null lobe is refused (null_transmission has no uv).
//  principled, principledthin: bsdf_principled.cpp.
//  mask             opacity (float or texture, default 0.5), nested: 1 BSDF.
//                   Pass-through with probability 1 - opacity.
//  normalmap        normalmap (texture of tangent-space normals), nested: 1.
//  bumpmap          one texture (a height field, any name), scale (1),
//                   nested: 1. Both: flip_invalid_normals (true),
//                   use_shadowing_function (true). normalmap and bumpmap
//                   perturb the hit's shading frame (Bsdf::perturb_frame);
//                   neither may sit inside a twosided (it would mirror wi
//                   first) or inside each other.
// Textured colours (BsdfDesc::textures; scene/texture.h): reflectance
// (diffuse), diffuse_reflectance (plastic, roughplastic) and
// specular_reflectance (conductor, roughconductor), evaluated at the
// BsdfContext's uv; and textured roughness alpha_u, alpha_v
// (roughconductor), read as Texture::eval_1 (as Mitsuba reads them). A
// lobe-selection weight that Mitsuba computes from a colour's mean uses the
// texture's mean(), as Mitsuba does.
// Alphas below 1e-4 are clamped to 1e-4 (Mitsuba does the same); negative or
// non-finite values of any parameter are rejected.
#include "scene/bsdf.h"

#include <array>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <tuple>

#include "core/warp.h"
#include "scene/bsdf_principled.h"
#include "scene/bsdf_util.h"
#include "scene/fresnel.h"
#include "scene/microfacet.h"
#include "scene/texture.h"

namespace rm {

namespace {

// ---------------------------------------------------------------------------
// Helpers (the shared ones are in bsdf_util.h)

using namespace bsdf_util;

// Relative IOR int_ior / ext_ior, validated.
float relative_ior(const BsdfDesc& d) {
    if (!std::isfinite(d.int_ior) || !(d.int_ior > 0.f)) fail(d, "int_ior", "must be finite and positive");
    if (!std::isfinite(d.ext_ior) || !(d.ext_ior > 0.f)) fail(d, "ext_ior", "must be finite and positive");
    return d.int_ior / d.ext_ior;
}

MicrofacetDistribution make_distribution(const BsdfDesc& d) {
    MicrofacetType type;
    if (d.distribution == "beckmann")
        type = MicrofacetType::Beckmann;
    else if (d.distribution == "ggx")
        type = MicrofacetType::GGX;
    else
        fail(d, "distribution", "must be \"beckmann\" or \"ggx\", got \"" + d.distribution + "\"");
    if (!std::isfinite(d.alpha_u) || d.alpha_u < 0.f) fail(d, "alpha_u", "must be finite and >= 0");
    if (!std::isfinite(d.alpha_v) || d.alpha_v < 0.f) fail(d, "alpha_v", "must be finite and >= 0");
    return MicrofacetDistribution(type, d.alpha_u, d.alpha_v, d.sample_visible);
}

// ---------------------------------------------------------------------------
// diffuse: Lambertian, f = reflectance / pi, cosine-weighted sampling
// (PBR4 sec. 9.2; Mitsuba src/bsdfs/diffuse.cpp).

class DiffuseBsdf final : public Bsdf {
public:
    explicit DiffuseBsdf(TexturedColor reflectance) : reflectance_(std::move(reflectance)) {
        flags_ = kDiffuseReflection;
        textured_ = reflectance_.textured();
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float, Vec2 u2) const override {
        BsdfSample bs;
        if (!(wi.z > 0.f)) return bs;
        bs.wo = warp::square_to_cosine_hemisphere(u2);
        bs.pdf_w = warp::square_to_cosine_hemisphere_pdf_w(bs.wo);
        bs.weight = reflectance_.eval(ctx.uv);  // (rho / pi) cos / (cos / pi)
        bs.sampled_flags = kDiffuseReflection;
        return sanitize(bs);
    }
    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!(wi.z > 0.f) || !(wo.z > 0.f)) return Color(0.f);
        return reflectance_.eval(ctx.uv) * (wo.z * kInvPi);
    }
    float pdf_w(const BsdfContext&, const Vec3& wi, const Vec3& wo) const override {
        if (!(wi.z > 0.f) || !(wo.z > 0.f)) return 0.f;
        return warp::square_to_cosine_hemisphere_pdf_w(wo);
    }

private:
    TexturedColor reflectance_;
};

// ---------------------------------------------------------------------------
// conductor: smooth metal, a single delta reflection weighted by the exact
// complex Fresnel reflectance (Mitsuba src/bsdfs/conductor.cpp).

class ConductorBsdf final : public Bsdf {
public:
    ConductorBsdf(const Color& eta, const Color& k, TexturedColor specular)
        : eta_(eta), k_(k), specular_(std::move(specular)) {
        flags_ = kDeltaReflection;
        textured_ = specular_.textured();
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float, Vec2) const override {
        BsdfSample bs;
        if (!(wi.z > 0.f)) return bs;
        bs.wo = reflect_local(wi);
        bs.pdf_w = 1.f;
        bs.is_delta = true;
        bs.sampled_flags = kDeltaReflection;
        bs.weight = specular_.eval(ctx.uv) * fresnel_conductor(wi.z, eta_, k_);
        return sanitize(bs);
    }
    Color eval(const BsdfContext&, const Vec3&, const Vec3&) const override { return Color(0.f); }
    float pdf_w(const BsdfContext&, const Vec3&, const Vec3&) const override { return 0.f; }

private:
    Color eta_, k_;
    TexturedColor specular_;
};

// ---------------------------------------------------------------------------
// roughconductor: Torrance-Sparrow microfacet reflection,
// f = F(wi.h) D(h) G(wi, wo, h) / (4 cos_i cos_o) (Walter et al. 2007, eq. 20),
// eval includes cos_o. Sampling: m from the VNDF (or D cos), wo = reflect(wi, m),
// pdf_w(wo) = pdf(m) / (4 wo.m) (Walter et al. 2007, eq. 14).
// Mitsuba src/bsdfs/roughconductor.cpp.

class RoughConductorBsdf final : public Bsdf {
public:
    // alpha_u, alpha_v: textured roughness (null: distr's own alphas).
    RoughConductorBsdf(const MicrofacetDistribution& distr, const Color& eta, const Color& k, TexturedColor specular,
                       std::shared_ptr<const Texture> alpha_u = nullptr,
                       std::shared_ptr<const Texture> alpha_v = nullptr)
        : distr_(distr),
          eta_(eta),
          k_(k),
          specular_(std::move(specular)),
          alpha_u_(std::move(alpha_u)),
          alpha_v_(std::move(alpha_v)) {
        flags_ = kGlossyReflection;
        textured_ = specular_.textured() || alpha_u_ || alpha_v_;
        anisotropic_ = alpha_u_ || alpha_v_ || distr_.alpha_u() != distr_.alpha_v();
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float, Vec2 u2) const override {
        BsdfSample bs;
        if (!(wi.z > 0.f)) return bs;
        const MicrofacetDistribution distr = distribution(ctx.uv);
        MicrofacetSample ms = distr.sample(wi, u2);
        if (!(ms.pdf_w > 0.f)) return bs;
        const Vec3 m = ms.m;
        bs.wo = reflect(wi, m);
        const float wo_m = dot(bs.wo, m);
        if (!(bs.wo.z > 0.f) || !(wo_m > 0.f)) return BsdfSample{};
        bs.pdf_w = ms.pdf_w / (4.f * wo_m);
        bs.sampled_flags = kGlossyReflection;
        // eval / pdf: with visible normals D G1(wi) cancels, leaving G1(wo)
        // (Heitz & d'Eon 2014, sec. 5); otherwise Walter et al. 2007, eq. 41.
        float w;
        if (distr.sample_visible())
            w = distr.G1(bs.wo, m);
        else
            w = distr.G(wi, bs.wo, m) * dot(wi, m) / (wi.z * m.z);
        bs.weight = specular_.eval(ctx.uv) * fresnel_conductor(dot(wi, m), eta_, k_) * w;
        return sanitize(bs);
    }

    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!(wi.z > 0.f) || !(wo.z > 0.f)) return Color(0.f);
        const Vec3 h = wi + wo;
        const float len = length(h);
        if (!(len > 0.f)) return Color(0.f);
        const Vec3 m = h / len;
        const MicrofacetDistribution distr = distribution(ctx.uv);
        const float D = distr.D(m);
        if (D == 0.f) return Color(0.f);
        const float G = distr.G(wi, wo, m);
        const float value = D * G / (4.f * wi.z);
        return finite_or_zero(specular_.eval(ctx.uv) * fresnel_conductor(dot(wi, m), eta_, k_) * value);
    }

    float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!(wi.z > 0.f) || !(wo.z > 0.f)) return 0.f;
        const MicrofacetDistribution distr = distribution(ctx.uv);
        const Vec3 h = wi + wo;
        const float len = length(h);
        if (!(len > 0.f)) return 0.f;
        const Vec3 m = h / len;
        // The side checks G1 applies in sample() must hold here too.
        const float wo_m = dot(wo, m);
        if (!(dot(wi, m) > 0.f) || !(wo_m > 0.f)) return 0.f;
        return finite_or_zero(distr.pdf_w(wi, m) / (4.f * wo_m));
    }

private:
    // The distribution at uv: the constructed one, or one with the textures'
    // alphas (Mitsuba's roughconductor reads alpha_u / alpha_v with eval_1
    // per query). A value, a few floats: no allocation.
    MicrofacetDistribution distribution(const SurfaceUv& uv) const {
        if (!alpha_u_ && !alpha_v_) return distr_;
        const float au = alpha_u_ ? alpha_u_->eval_1(uv) : distr_.alpha_u();
        const float av = alpha_v_ ? alpha_v_->eval_1(uv) : distr_.alpha_v();
        return MicrofacetDistribution(distr_.type(), au, av, distr_.sample_visible());
    }

    MicrofacetDistribution distr_;
    Color eta_, k_;
    TexturedColor specular_;
    std::shared_ptr<const Texture> alpha_u_, alpha_v_;
};

// ---------------------------------------------------------------------------
// dielectric: smooth interface, delta reflection and refraction chosen with
// probability F and 1 - F, so the weight is the lobe's albedo alone (Mitsuba
// src/bsdfs/dielectric.cpp). Radiance transport through the interface is
// scaled by (eta_i / eta_t)^2 = eta_ti^2 (Veach 1997, "Robust Monte Carlo
// Methods for Light Transport Simulation", sec. 5.2); importance transport is not.

class DielectricBsdf final : public Bsdf {
public:
    DielectricBsdf(float eta, const Color& spec_r, const Color& spec_t) : eta_(eta), spec_r_(spec_r), spec_t_(spec_t) {
        flags_ = kDeltaReflection | kDeltaTransmission;
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2) const override {
        const FresnelDielectric fr = fresnel_dielectric(wi.z, eta_);
        BsdfSample bs;
        bs.is_delta = true;
        // Strict '<' so that a lobe of probability 0 is never picked.
        if (u1 < fr.F) {
            bs.wo = reflect_local(wi);
            bs.pdf_w = fr.F;
            bs.weight = spec_r_;
            bs.sampled_flags = kDeltaReflection;
        } else {
            bs.wo = refract_local(wi, fr.cos_theta_t, fr.eta_ti);
            bs.pdf_w = 1.f - fr.F;
            bs.weight = spec_t_;
            if (ctx.mode == TransportMode::Radiance) bs.weight *= sqr(fr.eta_ti);
            bs.eta = fr.eta_it;
            bs.sampled_flags = kDeltaTransmission;
        }
        return sanitize(bs);
    }
    Color eval(const BsdfContext&, const Vec3&, const Vec3&) const override { return Color(0.f); }
    float pdf_w(const BsdfContext&, const Vec3&, const Vec3&) const override { return 0.f; }

private:
    float eta_;
    Color spec_r_, spec_t_;
};

// ---------------------------------------------------------------------------
// roughdielectric: Walter et al. 2007, "Microfacet Models for Refraction
// through Rough Surfaces". Reflection f_r (eq. 20) with h_r (eq. 13), refraction
// f_t (eq. 21) with h_t = -(wi + eta wo) (eq. 16); the half-vector Jacobians
// are eqs. 14 and 17. The lobe is chosen with probability F(wi.m) after m is
// sampled (as Mitsuba). In Radiance mode f_t carries the extra 1/eta^2 of
// radiance compression that the paper leaves out (Mitsuba
// src/bsdfs/roughdielectric.cpp; Veach 1997, sec. 5.2).

class RoughDielectricBsdf final : public Bsdf {
public:
    RoughDielectricBsdf(const MicrofacetDistribution& distr, float eta, const Color& spec_r, const Color& spec_t)
        : distr_(distr), eta_(eta), spec_r_(spec_r), spec_t_(spec_t) {
        flags_ = kGlossyReflection | kGlossyTransmission;
        anisotropic_ = distr_.alpha_u() != distr_.alpha_v();
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        BsdfSample bs;
        const float cos_i = wi.z;
        if (cos_i == 0.f || !std::isfinite(cos_i)) return bs;  // perfectly grazing

        // Sample m on the side of wi (microfacets face the macro normal's side).
        const MicrofacetDistribution sdistr = sampling_distribution(cos_i);
        const Vec3 wi_up = wi * mulsign(1.f, cos_i);
        const MicrofacetSample ms = sdistr.sample(wi_up, u2);
        if (!(ms.pdf_w > 0.f)) return bs;
        const Vec3 m = ms.m;

        const float wi_m = dot(wi, m);
        const FresnelDielectric fr = fresnel_dielectric(wi_m, eta_);
        float dwh_dwo;
        Color weight;
        if (u1 < fr.F) {
            bs.wo = reflect(wi, m);
            bs.sampled_flags = kGlossyReflection;
            bs.pdf_w = ms.pdf_w * fr.F;
            dwh_dwo = 1.f / (4.f * dot(bs.wo, m));  // eq. 14
            weight = spec_r_;
        } else {
            bs.wo = refract(wi, m, fr.cos_theta_t, fr.eta_ti);
            bs.sampled_flags = kGlossyTransmission;
            bs.eta = fr.eta_it;
            bs.pdf_w = ms.pdf_w * (1.f - fr.F);
            const float wo_m = dot(bs.wo, m);
            dwh_dwo = sqr(fr.eta_it) * wo_m / sqr(wi_m + fr.eta_it * wo_m);  // eq. 17
            weight = spec_t_;
            if (ctx.mode == TransportMode::Radiance) weight *= sqr(fr.eta_ti);
        }
        bs.pdf_w *= std::fabs(dwh_dwo);

        // eval / pdf. With visible normals, D G1(wi) |wi.m| / |cos_i| cancels and
        // G1(wo) is left (Heitz & d'Eon 2014, sec. 5). Sampling D cos from a widened
        // distribution leaves G |wi.m| / (|cos_i| cos_m) (Walter eq. 41) times
        // D / D_widened; Mitsuba omits the latter ratio (its weights there are not
        // eval / pdf), we keep it so that weight == eval / pdf always holds.
        float geometric;
        if (distr_.sample_visible()) {
            geometric = distr_.G1(bs.wo, m);
        } else {
            const float Ds = sdistr.D(m);
            if (!(Ds > 0.f)) return BsdfSample{};
            geometric = distr_.G(wi, bs.wo, m) * std::fabs(wi_m) / (std::fabs(cos_i) * m.z) * (distr_.D(m) / Ds);
        }
        // G1 = 0: wo left on the wrong side of the macro surface (e.g. a reflection
        // through it). pdf_w() is 0 there too, so the sample is a failure.
        if (!(geometric > 0.f)) return BsdfSample{};
        bs.weight = weight * geometric;
        return sanitize(bs);
    }

    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        Color value;
        float pdf;
        eval_pdf(ctx, wi, wo, &value, &pdf);
        return value;
    }
    float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        Color value;
        float pdf;
        eval_pdf(ctx, wi, wo, &value, &pdf);
        return pdf;
    }

private:
    // Walter et al. 2007 widen the lobe for D cos sampling (end of sec. 5.3).
    MicrofacetDistribution sampling_distribution(float cos_i) const {
        MicrofacetDistribution d = distr_;
        if (!distr_.sample_visible()) d.scale_alpha(1.2f - 0.2f * std::sqrt(std::fabs(cos_i)));
        return d;
    }

    void eval_pdf(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo, Color* value, float* pdf) const {
        *value = Color(0.f);
        *pdf = 0.f;
        const float cos_i = wi.z, cos_o = wo.z;
        if (cos_i == 0.f) return;
        const bool is_reflect = cos_i * cos_o > 0.f;
        // Relative IOR across the interface in the direction wi -> wo.
        const float eta = cos_i > 0.f ? eta_ : 1.f / eta_;

        // Generalised half vector (eqs. 13 and 16), oriented like the macro normal.
        Vec3 h = is_reflect ? wi + wo : wi + wo * eta;
        const float len = length(h);
        if (!(len > 0.f) || !std::isfinite(len)) return;
        Vec3 m = h / len;
        m = m * mulsign(1.f, m.z);

        const float wi_m = dot(wi, m), wo_m = dot(wo, m);
        // Micro- and macro-surface must agree on the side of each direction
        // (the condition G1 checks; needed in the pdf as well).
        if (!(wi_m * cos_i > 0.f) || !(wo_m * cos_o > 0.f)) return;

        const float D = distr_.D(m);
        if (D == 0.f) return;
        const float F = fresnel_dielectric(wi_m, eta_).F;
        const float G = distr_.G(wi, wo, m);

        const MicrofacetDistribution sdistr = sampling_distribution(cos_i);
        const Vec3 wi_up = wi * mulsign(1.f, cos_i);
        const float pdf_m = sdistr.pdf_w(wi_up, m);

        if (is_reflect) {
            *value = spec_r_ * (F * D * G / (4.f * std::fabs(cos_i)));  // eq. 20 times |cos_o|
            *pdf = pdf_m * F / (4.f * std::fabs(wo_m));                 // eq. 14
        } else {
            const float denom = sqr(wi_m + eta * wo_m);
            if (!(denom > 0.f)) return;
            const float scale = ctx.mode == TransportMode::Radiance ? 1.f / sqr(eta) : 1.f;
            // eq. 21 times |cos_o|.
            const float ft = std::fabs(scale * (1.f - F) * D * G * sqr(eta) * wi_m * wo_m / (cos_i * denom));
            *value = spec_t_ * ft;
            *pdf = pdf_m * (1.f - F) * std::fabs(sqr(eta) * wo_m / denom);  // eq. 17
        }
        *value = finite_or_zero(*value);
        *pdf = finite_or_zero(*pdf);
    }

    MicrofacetDistribution distr_;
    float eta_;
    Color spec_r_, spec_t_;
};

// ---------------------------------------------------------------------------
// thindielectric: a thin slab with two parallel smooth interfaces. Summing the
// internal bounces, R' = R + T^2 R / (1 - R^2) = 2R / (1 + R), T' = 1 - R'
// (no absorption); transmission leaves along -wi (the two refractions undo each
// other) and is a kNull lobe, as Mitsuba's (src/bsdfs/thindielectric.cpp).

class ThinDielectricBsdf final : public Bsdf {
public:
    ThinDielectricBsdf(float eta, const Color& spec_r, const Color& spec_t)
        : eta_(eta), spec_r_(spec_r), spec_t_(spec_t) {
        flags_ = kDeltaReflection | kNull;
    }

    BsdfSample sample(const BsdfContext&, const Vec3& wi, float u1, Vec2) const override {
        const float R = slab_reflectance(wi.z);
        BsdfSample bs;
        bs.is_delta = true;
        if (u1 < R) {
            bs.wo = reflect_local(wi);
            bs.pdf_w = R;
            bs.weight = spec_r_;
            bs.sampled_flags = kDeltaReflection;
        } else {
            bs.wo = -wi;
            bs.pdf_w = 1.f - R;
            bs.weight = spec_t_;
            bs.sampled_flags = kNull;
        }
        return sanitize(bs);
    }
    Color eval(const BsdfContext&, const Vec3&, const Vec3&) const override { return Color(0.f); }
    float pdf_w(const BsdfContext&, const Vec3&, const Vec3&) const override { return 0.f; }

    Color null_transmission(const BsdfContext&, float cos_theta) const override {
        return spec_t_ * (1.f - slab_reflectance(cos_theta));
    }

private:
    // R' = 2R / (1 + R) at incidence |cos theta|.
    float slab_reflectance(float cos_theta) const {
        const float R = fresnel_dielectric(std::fabs(cos_theta), eta_).F;
        return 2.f * R / (1.f + R);
    }
    float eta_;
    Color spec_r_, spec_t_;
};

// ---------------------------------------------------------------------------
// The Lambertian base under a dielectric coat, shared by plastic and
// roughplastic (Weidlich & Wilkie 2007; Mitsuba's plastic.cpp and
// roughplastic.cpp): the base's albedo rho normalised by the coat's
// internal reflectance R_int, rho / (1 - R_int) or, nonlinear,
// rho / (1 - rho R_int); and the probability of sampling the coat's lobe,
// r s / (r s + t (1 - s)) with r and t the coat's reflected and transmitted
// fractions at wi and s = mean(spec) / (mean(diffuse) + mean(spec)).
class CoatedBase {
public:
    CoatedBase(TexturedColor diffuse, const Color& specular, float eta, float internal_reflectance, bool nonlinear)
        : diffuse_(std::move(diffuse)),
          specular_(specular),
          inv_eta2_(1.f / (eta * eta)),
          r_int_(internal_reflectance),
          nonlinear_(nonlinear) {
        const float d_mean = diffuse_.mean(), s_mean = average(specular);
        weight_ = (d_mean + s_mean) > 0.f ? s_mean / (d_mean + s_mean) : 0.5f;
        norm_ = normalised(diffuse_.value);
    }
    float prob_coat(float reflected, float transmitted) const {
        const float ps = reflected * weight_;
        const float pd = transmitted * (1.f - weight_);
        return ps + pd > 0.f ? ps / (ps + pd) : 0.5f;
    }
    // Precomputed when untextured; per query from the texture otherwise.
    Color diffuse_norm(const SurfaceUv& uv) const {
        return diffuse_.textured() ? normalised(diffuse_.texture->eval(uv)) : norm_;
    }
    bool textured() const { return diffuse_.textured(); }
    const Color& specular() const { return specular_; }
    float inv_eta2() const { return inv_eta2_; }

private:
    // Non-physical albedos (rho R_int >= 1 with nonlinear) would make it
    // infinite or negative: those become 0 rather than NaN/negative weights.
    Color normalised(const Color& rho) const {
        const Color denom = nonlinear_ ? Color(1.f) - rho * r_int_ : Color(1.f - r_int_);
        return vmax(finite_or_zero(rho / denom), Color(0.f));
    }
    TexturedColor diffuse_;
    Color specular_, norm_;
    float inv_eta2_, r_int_, weight_ = 0.5f;
    bool nonlinear_;
};

// ---------------------------------------------------------------------------
// plastic: smooth dielectric coating over a Lambertian base, with the coating's
// internal reflections summed in closed form (Weidlich & Wilkie 2007,
// "Arbitrarily Layered Micro-Facet Surfaces"; Mitsuba src/bsdfs/plastic.cpp):
// f_d = rho / (1 - Fdr_int) (or rho / (1 - rho Fdr_int) when nonlinear)
//       * (1 - F(cos_i)) (1 - F(cos_o)) / eta^2 / pi.
// The specular lobe is picked with probability proportional to
// F(cos_i) s against (1 - F(cos_i)) (1 - s), s = mean(spec) / (mean(diffuse) + mean(spec)).

class PlasticBsdf final : public Bsdf {
public:
    PlasticBsdf(float eta, TexturedColor diffuse, const Color& specular, bool nonlinear)
        : eta_(eta), coat_(std::move(diffuse), specular, eta, fresnel_diffuse_reflectance(1.f / eta), nonlinear) {
        flags_ = kDeltaReflection | kDiffuseReflection;
        textured_ = coat_.textured();
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        BsdfSample bs;
        if (!(wi.z > 0.f)) return bs;
        const float f_i = fresnel_dielectric(wi.z, eta_).F;
        const float p_spec = prob_specular(f_i), p_diff = 1.f - p_spec;
        if (u1 < p_spec) {
            bs.wo = reflect_local(wi);
            bs.pdf_w = p_spec;
            bs.is_delta = true;
            bs.sampled_flags = kDeltaReflection;
            bs.weight = coat_.specular() * (f_i / p_spec);
        } else {
            bs.wo = warp::square_to_cosine_hemisphere(u2);
            bs.pdf_w = p_diff * warp::square_to_cosine_hemisphere_pdf_w(bs.wo);
            bs.sampled_flags = kDiffuseReflection;
            const float f_o = fresnel_dielectric(bs.wo.z, eta_).F;
            bs.weight = coat_.diffuse_norm(ctx.uv) * (coat_.inv_eta2() * (1.f - f_i) * (1.f - f_o) / p_diff);
        }
        return sanitize(bs);
    }
    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!(wi.z > 0.f) || !(wo.z > 0.f)) return Color(0.f);
        const float f_i = fresnel_dielectric(wi.z, eta_).F, f_o = fresnel_dielectric(wo.z, eta_).F;
        return finite_or_zero(coat_.diffuse_norm(ctx.uv) *
                              (wo.z * kInvPi * coat_.inv_eta2() * (1.f - f_i) * (1.f - f_o)));
    }
    float pdf_w(const BsdfContext&, const Vec3& wi, const Vec3& wo) const override {
        if (!(wi.z > 0.f) || !(wo.z > 0.f)) return 0.f;
        const float f_i = fresnel_dielectric(wi.z, eta_).F;
        return warp::square_to_cosine_hemisphere_pdf_w(wo) * (1.f - prob_specular(f_i));
    }

private:
    float prob_specular(float f_i) const { return coat_.prob_coat(f_i, 1.f - f_i); }

    float eta_;
    CoatedBase coat_;  // R_int = Fdr_int, the smooth coat's diffuse Fresnel reflectance from inside
};

// ---------------------------------------------------------------------------
// roughplastic: rough dielectric coating over a Lambertian base (Weidlich &
// Wilkie 2007, "Arbitrarily Layered Micro-Facet Surfaces"; Mitsuba 3
// src/bsdfs/roughplastic.cpp, whose model this is, term for term):
//   specular: f_s = s F(wi.h) D(h) G(wi, wo, h) / (4 cos_i cos_o)
//             (Walter et al. 2007, "Microfacet Models for Refraction through
//             Rough Surfaces", eq. 20), h = normalize(wi + wo);
//   diffuse:  f_d = rho / (1 - R_int) (or rho / (1 - rho R_int) when nonlinear)
//             * T(cos_i) T(cos_o) / eta^2 / pi,
// where T(mu) is the coating's single-scattering transmittance from outside
// at incidence mu (microfacet_transmittance(), eta) and R_int its internal
// cosine-weighted hemispherical reflectance, 2 int R(mu) mu dmu with R the
// internal single-scattering reflectance (microfacet_reflectance(), 1 / eta).
// As Mitsuba, T is tabulated at 64 cosines mu_k = max(1e-6, k / 63) and
// interpolated linearly; R_int is 2 mean_k(R(mu_k) mu_k) over the same nodes
// (Mitsuba's sum, with both end nodes at full weight, kept so that R_int agrees).
// Mitsuba integrates with a Gauss-Legendre rule over its visible-normal
// sampler's unit square (32^2 nodes where the relative IOR exceeds 1, 128^2
// otherwise); we compute the same integrals, with our own sampler
// (microfacet.h), at construction, and cache them per (distribution, alpha, eta).
// Sampling: the glossy lobe (visible normals or D cos, reflected) with
// probability p_s = (1 - T(cos_i)) w / ((1 - T(cos_i)) w + T(cos_i) (1 - w)),
// w = mean(spec) / (mean(diffuse) + mean(spec)), else cosine-weighted; the
// pdf is the mixture of both and a sample's weight is eval / pdf (as Mitsuba).
// The eval is reciprocal (both terms are symmetric in cos_i, cos_o) and the
// same in both transport modes.

struct RoughPlasticTables {
    static constexpr int kRes = 64;
    std::array<float, kRes> transmittance{};  // T(mu_k)
    float internal_reflectance = 0.f;         // R_int
};

std::shared_ptr<const RoughPlasticTables> rough_plastic_tables(MicrofacetType type, float alpha, float eta) {
    // Computing them costs ~5 10^5 visible-normal samples: a scene with many
    // equal coatings, or a test building the same BSDF again, pays once.
    static std::mutex mutex;
    static std::map<std::tuple<int, float, float>, std::shared_ptr<const RoughPlasticTables>> cache;
    const auto key = std::make_tuple(int(type), alpha, eta);
    {
        std::lock_guard<std::mutex> lock(mutex);
        auto it = cache.find(key);
        if (it != cache.end()) return it->second;
    }
    auto t = std::make_shared<RoughPlasticTables>();
    const MicrofacetDistribution distr(type, alpha, alpha, true);
    // Mitsuba's resolutions: the rule needs more nodes where total internal
    // reflection puts a kink into the integrand (relative IOR < 1).
    const int res_ext = eta > 1.f ? 32 : 128, res_int = eta < 1.f ? 32 : 128;
    double r_int = 0.0;
    for (int k = 0; k < RoughPlasticTables::kRes; ++k) {
        const float mu = std::max(1e-6f, float(k) / float(RoughPlasticTables::kRes - 1));
        const Vec3 wi(std::sqrt(1.f - mu * mu), 0.f, mu);
        t->transmittance[size_t(k)] = float(microfacet_transmittance(distr, wi, eta, res_ext));
        r_int += microfacet_reflectance(distr, wi, 1.f / eta, res_int) * mu;
    }
    t->internal_reflectance = float(2.0 * r_int / RoughPlasticTables::kRes);
    std::lock_guard<std::mutex> lock(mutex);
    return cache.emplace(key, std::move(t)).first->second;
}

class RoughPlasticBsdf final : public Bsdf {
public:
    RoughPlasticBsdf(const MicrofacetDistribution& distr, float eta, TexturedColor diffuse, const Color& specular,
                     bool nonlinear)
        : distr_(distr),
          tables_(rough_plastic_tables(distr.type(), distr.alpha_u(), eta)),
          eta_(eta),
          coat_(std::move(diffuse), specular, eta, tables_->internal_reflectance, nonlinear) {
        flags_ = kGlossyReflection | kDiffuseReflection;
        textured_ = coat_.textured();
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        BsdfSample bs;
        if (!(wi.z > 0.f)) return bs;
        if (u1 < prob_specular(wi.z)) {
            const MicrofacetSample ms = distr_.sample(wi, u2);
            if (!(ms.pdf_w > 0.f)) return bs;
            bs.wo = reflect(wi, ms.m);
            bs.sampled_flags = kGlossyReflection;
        } else {
            bs.wo = warp::square_to_cosine_hemisphere(u2);
            bs.sampled_flags = kDiffuseReflection;
        }
        // The mixture's density and value, so that weight = eval / pdf exactly.
        bs.pdf_w = pdf_w(ctx, wi, bs.wo);
        if (!(bs.pdf_w > 0.f)) return BsdfSample{};
        bs.weight = eval(ctx, wi, bs.wo) / bs.pdf_w;
        return sanitize(bs);
    }

    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!(wi.z > 0.f) || !(wo.z > 0.f)) return Color(0.f);
        Color value(0.f);
        const Vec3 h = wi + wo;
        const float len = length(h);
        if (len > 0.f) {
            const Vec3 m = h / len;
            const float D = distr_.D(m);
            if (D > 0.f) {
                const float F = fresnel_dielectric(dot(wi, m), eta_).F;
                value = coat_.specular() * (F * D * distr_.G(wi, wo, m) / (4.f * wi.z));  // eq. 20 times cos_o
            }
        }
        const float t = transmittance(wi.z) * transmittance(wo.z);
        value += coat_.diffuse_norm(ctx.uv) * (kInvPi * coat_.inv_eta2() * wo.z * t);
        return finite_or_zero(value);
    }

    float pdf_w(const BsdfContext&, const Vec3& wi, const Vec3& wo) const override {
        if (!(wi.z > 0.f) || !(wo.z > 0.f)) return 0.f;
        const float p_spec = prob_specular(wi.z);
        float pdf = (1.f - p_spec) * warp::square_to_cosine_hemisphere_pdf_w(wo);
        const Vec3 h = wi + wo;
        const float len = length(h);
        if (len > 0.f) {
            const Vec3 m = h / len;
            const float wo_m = dot(wo, m);
            // Walter et al. 2007, eq. 14: pdf(wo) = pdf(m) / (4 wo.m).
            if (wo_m > 0.f) pdf += p_spec * distr_.pdf_w(wi, m) / (4.f * wo_m);
        }
        return finite_or_zero(pdf);
    }

private:
    // Mitsuba's lerp_gather: linear interpolation in the table over [0, 1].
    float transmittance(float cos_theta) const {
        const float x = cos_theta * float(RoughPlasticTables::kRes - 1);
        const int i = std::min(int(x), RoughPlasticTables::kRes - 2);
        const float f = x - float(i);
        const auto& t = tables_->transmittance;
        return (1.f - f) * t[size_t(i)] + f * t[size_t(i) + 1];
    }
    float prob_specular(float cos_i) const {
        const float t_i = transmittance(cos_i);
        return coat_.prob_coat(1.f - t_i, t_i);
    }

    MicrofacetDistribution distr_;
    std::shared_ptr<const RoughPlasticTables> tables_;  // before coat_, which reads its R_int
    float eta_;
    CoatedBase coat_;
};

// ---------------------------------------------------------------------------
// twosided: makes a one-sided BRDF two-sided (Mitsuba src/bsdfs/twosided.cpp).
// One nested BSDF: wi is mirrored to the front (z -> |z|) and wo follows.
// Two: the front one for wi.z > 0, the back one for wi.z < 0 with wi.z and
// wo.z negated (only z: tangents, hence anisotropy axes, are kept, as Mitsuba).

class TwoSidedBsdf final : public Bsdf {
public:
    TwoSidedBsdf(std::unique_ptr<Bsdf> front, std::unique_ptr<Bsdf> back)
        : front_(std::move(front)), back_(std::move(back)) {
        flags_ = front_->flags() | (back_ ? back_->flags() : 0u);
        textured_ = front_->textured() || (back_ && back_->textured());
        anisotropic_ = front_->anisotropic() || (back_ && back_->anisotropic());
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        if (!back_) {
            const Vec3 w(wi.x, wi.y, std::fabs(wi.z));
            BsdfSample bs = front_->sample(ctx, w, u1, u2);
            bs.wo.z = mulsign(bs.wo.z, wi.z);
            return bs;
        }
        if (wi.z > 0.f) return front_->sample(ctx, wi, u1, u2);
        if (wi.z < 0.f) {
            BsdfSample bs = back_->sample(ctx, Vec3(wi.x, wi.y, -wi.z), u1, u2);
            bs.wo.z = -bs.wo.z;
            return bs;
        }
        return BsdfSample{};
    }
    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!back_) return front_->eval(ctx, Vec3(wi.x, wi.y, std::fabs(wi.z)), Vec3(wo.x, wo.y, mulsign(wo.z, wi.z)));
        if (wi.z > 0.f) return front_->eval(ctx, wi, wo);
        if (wi.z < 0.f) return back_->eval(ctx, Vec3(wi.x, wi.y, -wi.z), Vec3(wo.x, wo.y, -wo.z));
        return Color(0.f);
    }
    float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!back_) return front_->pdf_w(ctx, Vec3(wi.x, wi.y, std::fabs(wi.z)), Vec3(wo.x, wo.y, mulsign(wo.z, wi.z)));
        if (wi.z > 0.f) return front_->pdf_w(ctx, wi, wo);
        if (wi.z < 0.f) return back_->pdf_w(ctx, Vec3(wi.x, wi.y, -wi.z), Vec3(wo.x, wo.y, -wo.z));
        return 0.f;
    }

private:
    std::unique_ptr<Bsdf> front_, back_;  // back_ == nullptr: front_ on both sides
};

// ---------------------------------------------------------------------------
// blendbsdf: (1 - w) f_0 + w f_1, w = clamp(weight, 0, 1) (Mitsuba
// src/bsdfs/blendbsdf.cpp). Sampling picks BSDF 1 with probability w, as
// Mitsuba; unlike Mitsuba, whose sample weight is the picked BSDF's own, a
// smooth sample's pdf is the mixture's, (1 - w) pdf_0 + w pdf_1, and its
// weight the mixture's eval / pdf (the same expectation; weight = eval /
// pdf holds, as every estimator's MIS assumes). A delta sample keeps its
// weight, its probability scaled by that of its BSDF.

class BlendBsdf final : public Bsdf {
public:
    BlendBsdf(TexturedFloat weight, std::unique_ptr<Bsdf> b0, std::unique_ptr<Bsdf> b1)
        : weight_(std::move(weight)), b0_(std::move(b0)), b1_(std::move(b1)) {
        flags_ = b0_->flags() | b1_->flags();
        textured_ = weight_.textured() || b0_->textured() || b1_->textured();
        anisotropic_ = b0_->anisotropic() || b1_->anisotropic();
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        const float w = weight(ctx.uv);
        // Mitsuba's split of u1: BSDF 1 on [0, w], BSDF 0 above, each
        // rescaled to [0, 1).
        const bool first = u1 > w;
        const float p = first ? 1.f - w : w;
        if (!(p > 0.f)) return BsdfSample{};
        BsdfSample bs = first ? b0_->sample(ctx, wi, (u1 - w) / p, u2) : b1_->sample(ctx, wi, u1 / p, u2);
        if (!(bs.pdf_w > 0.f)) return BsdfSample{};
        if (bs.is_delta) {
            bs.pdf_w *= p;
            return sanitize(bs);
        }
        Color value;
        mix(ctx, wi, bs.wo, w, &value, &bs.pdf_w);
        if (!(bs.pdf_w > 0.f)) return BsdfSample{};
        bs.weight = value / bs.pdf_w;
        return sanitize(bs);
    }
    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        Color value;
        float pdf;
        mix(ctx, wi, wo, weight(ctx.uv), &value, &pdf);
        return value;
    }
    float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        Color value;
        float pdf;
        mix(ctx, wi, wo, weight(ctx.uv), &value, &pdf);
        return pdf;
    }
    // Only with a plain weight (make_bsdf refuses a textured one here).
    Color null_transmission(const BsdfContext& ctx, float cos_theta) const override {
        const float w = clamp(weight_.value, 0.f, 1.f);
        return b0_->null_transmission(ctx, cos_theta) * (1.f - w) + b1_->null_transmission(ctx, cos_theta) * w;
    }

private:
    float weight(const SurfaceUv& uv) const { return clamp(weight_.eval(uv), 0.f, 1.f); }
    void mix(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo, float w, Color* value, float* pdf) const {
        *value = b0_->eval(ctx, wi, wo) * (1.f - w) + b1_->eval(ctx, wi, wo) * w;
        *pdf = b0_->pdf_w(ctx, wi, wo) * (1.f - w) + b1_->pdf_w(ctx, wi, wo) * w;
    }

    TexturedFloat weight_;
    std::unique_ptr<Bsdf> b0_, b1_;
};

// ---------------------------------------------------------------------------
// null: an invisible surface (medium boundaries); a forward delta of weight 1
// (Mitsuba src/bsdfs/null.cpp).

class NullBsdf final : public Bsdf {
public:
    NullBsdf() { flags_ = kNull; }

    BsdfSample sample(const BsdfContext&, const Vec3& wi, float, Vec2) const override {
        BsdfSample bs;
        bs.wo = -wi;
        bs.weight = Color(1.f);
        bs.pdf_w = 1.f;
        bs.is_delta = true;
        bs.sampled_flags = kNull;
        return bs;
    }
    Color eval(const BsdfContext&, const Vec3&, const Vec3&) const override { return Color(0.f); }
    float pdf_w(const BsdfContext&, const Vec3&, const Vec3&) const override { return 0.f; }
};

// ---------------------------------------------------------------------------
// mask: an opacity mask over a nested BSDF (Mitsuba 3 src/bsdfs/mask.cpp):
// with probability 1 - opacity the surface is a forward delta of weight 1
// (a kNull lobe, as null), else the nested BSDF scatters; eval and pdf are
// the nested ones times opacity, and a nested sample's pdf_w carries the
// opacity too (Mitsuba's sample() leaves it out, which makes its MIS
// weights disagree with pdf() where 0 < opacity < 1). opacity is a float
// or a texture read as eval_1, clamped to [0, 1] (as Mitsuba). A shadow
// ray keeps 1 - opacity (1 - nested null transmission) where an
// estimator lets it through null lobes (Mitsuba's eval_null_transmission).

class MaskBsdf final : public Bsdf {
public:
    MaskBsdf(std::unique_ptr<Bsdf> nested, float opacity, std::shared_ptr<const Texture> opacity_tex)
        : nested_(std::move(nested)), opacity_(opacity), tex_(std::move(opacity_tex)) {
        flags_ = nested_->flags() | kNull;
        textured_ = tex_ != nullptr || nested_->textured();
        anisotropic_ = nested_->anisotropic();
        perturbs_frame_ = nested_->perturbs_frame();
        frame_follows_wi_ = nested_->frame_follows_wi();
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        const float o = opacity(ctx.uv);
        if (u1 < o) {
            // u1 / o reuses the lobe choice's number, kept below 1.
            BsdfSample bs = nested_->sample(ctx, wi, std::min(u1 / o, 0x1.fffffep-1f), u2);
            bs.pdf_w *= o;
            return sanitize(bs);
        }
        BsdfSample bs;
        bs.wo = -wi;
        bs.weight = Color(1.f);
        bs.pdf_w = 1.f - o;
        bs.is_delta = true;
        bs.sampled_flags = kNull;
        return sanitize(bs);
    }
    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        const float o = opacity(ctx.uv);
        return o > 0.f ? nested_->eval(ctx, wi, wo) * o : Color(0.f);
    }
    float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        const float o = opacity(ctx.uv);
        return o > 0.f ? nested_->pdf_w(ctx, wi, wo) * o : 0.f;
    }
    Color null_transmission(const BsdfContext& ctx, float cos_theta) const override {
        return Color(1.f) - (Color(1.f) - nested_->null_transmission(ctx, cos_theta)) * opacity(ctx.uv);
    }
    void perturb_frame(Interaction& it) const override { nested_->perturb_frame(it); }

private:
    float opacity(const SurfaceUv& uv) const {
        const float o = tex_ ? tex_->eval_1(uv) : opacity_;
        return std::min(std::max(o, 0.f), 1.f);
    }
    std::unique_ptr<Bsdf> nested_;
    float opacity_;
    std::shared_ptr<const Texture> tex_;
};

// ---------------------------------------------------------------------------
// normalmap and bumpmap (Mitsuba 3.9 src/bsdfs/normalmap.cpp, bumpmap.cpp,
// normalmap_helpers.h): the nested BSDF in a perturbed shading frame. The
// frame is applied to the hit itself (perturb_frame, from
// Scene::intersect), so the nested BSDF's queries arrive in it, and so do
// the adjoint shading-normal correction of light paths and the estimators'
// cosines. The perturbed normal n', in the local coordinates of the hit's
// shading frame (whose tangent follows dp/du: anisotropic_):
//  normalmap: 2 rgb - 1 of the `normalmap` texture at uv;
//  bumpmap:   with (g_u, g_v) = scale * the height texture's uv gradient,
//             dp_du' = dp_du + n_s (g_u - n_s . dp_du), dp_dv' likewise,
//             n' = dp_du' x dp_dv' turned to the geometric normal's side
//             (Blinn 1978, "Simulation of Wrinkled Surfaces").
// flip_invalid_normals (default true): where the arriving direction wi lies
// on different sides of the unperturbed and the perturbed normal, n' is
// mirrored about the unperturbed one, (x, y, z) -> (-x, -y, z) (Schuessler
// et al. 2017, "Microfacet-based Normal Mapping for Robust Monte Carlo Path
// Tracing", as Mitsuba's fold). Then s' = normalize(e_x - n' n'_x),
// t' = n' x s' (bumpmap: dp_du in place of e_x, see tangent_seed).
// Directions on different sides of the unperturbed and the
// perturbed normal carry nothing (Mitsuba checks the light-side direction;
// we check both, which differs only for nested BSDFs that are not one-sided
// reflectors, and keeps pdf_w the density of sample()'s non-zero results in
// both transport modes). use_shadowing_function (default true): the value
// is multiplied by Conty Estevez, Lecocq and Stein 2019's ("A
// Microfacet-Based Shadowing Function to Solve the Bump Terminator
// Problem", Ray Tracing Gems ch. 12) G = 2 / (1 + sqrt(1 + a2 tan2(w))),
// a2 = min(1, tan2(n') / 8), angles against the unperturbed normal, w the
// light-side direction (wo in radiance transport, wi in importance
// transport: one integrand for both, as the adjoint needs).

class FrameMapBsdf : public Bsdf {
public:
    FrameMapBsdf(std::unique_ptr<Bsdf> nested, bool flip, bool shadowing)
        : nested_(std::move(nested)), flip_(flip), shadowing_(shadowing) {
        flags_ = nested_->flags();
        textured_ = true;
        anisotropic_ = true;
        perturbs_frame_ = true;
        frame_follows_wi_ = flip;
    }
    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        if (!same_side(ctx, wi)) return BsdfSample{};
        BsdfSample bs = nested_->sample(ctx, wi, u1, u2);
        if (!(bs.pdf_w > 0.f) || !same_side(ctx, bs.wo)) return BsdfSample{};
        if (shadowing_) bs.weight *= shadow(ctx, ctx.mode == TransportMode::Radiance ? bs.wo : wi);
        return bs;
    }
    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!same_side(ctx, wi) || !same_side(ctx, wo)) return Color(0.f);
        Color v = nested_->eval(ctx, wi, wo);
        if (shadowing_) v *= shadow(ctx, ctx.mode == TransportMode::Radiance ? wo : wi);
        return v;
    }
    float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        if (!same_side(ctx, wi) || !same_side(ctx, wo)) return 0.f;
        return nested_->pdf_w(ctx, wi, wo);
    }
    Color null_transmission(const BsdfContext& ctx, float cos_theta) const override {
        return nested_->null_transmission(ctx, cos_theta);
    }
    void perturb_frame(Interaction& it) const override {
        Vec3 n = mapped_normal(it);
        if (flip_) {
            const Vec3 wi = it.sh.to_local(it.wi);
            if (wi.z * dot(wi, n) <= 0.f) n = Vec3(-n.x, -n.y, n.z);
        }
        const float len = length(n);
        n = len > 0.f && std::isfinite(len) ? n / len : Vec3(0.f, 0.f, 1.f);
        Vec3 s = tangent_seed(it) - n * dot(n, tangent_seed(it));
        const float ls = length(s);
        s = ls > 0.f && std::isfinite(ls) ? s / ls : Vec3(0.f, 1.f, 0.f);
        const Vec3 t = cross(n, s);
        // The unperturbed normal e_z seen from the perturbed local frame.
        it.n_base = Vec3(s.z, t.z, n.z);
        Frame f;
        f.n = it.sh.to_world(n);
        f.s = it.sh.to_world(s);
        f.t = it.sh.to_world(t);
        it.sh = f;
    }

protected:
    // n' in the local coordinates of it.sh (unnormalised).
    virtual Vec3 mapped_normal(const Interaction& it) const = 0;
    // The vector s' is made orthogonal to n' from: the shading tangent e_x.
    virtual Vec3 tangent_seed(const Interaction&) const { return Vec3(1.f, 0.f, 0.f); }

private:
    // w on the same side of the unperturbed normal as of the perturbed one.
    static bool same_side(const BsdfContext& ctx, const Vec3& w) { return w.z * dot(w, ctx.n_base) > 0.f; }
    static float tan2(float c) { return std::max(0.f, 1.f - c * c) / (c * c); }
    static float shadow(const BsdfContext& ctx, const Vec3& w) {
        const float a2 = std::min(0.125f * tan2(ctx.n_base.z), 1.f);
        return 2.f / (1.f + std::sqrt(1.f + a2 * tan2(dot(w, ctx.n_base))));
    }

    std::unique_ptr<Bsdf> nested_;
    bool flip_, shadowing_;
};

class NormalMapBsdf final : public FrameMapBsdf {
public:
    NormalMapBsdf(std::unique_ptr<Bsdf> nested, bool flip, bool shadowing, std::shared_ptr<const Texture> normals)
        : FrameMapBsdf(std::move(nested), flip, shadowing), normals_(std::move(normals)) {}

protected:
    Vec3 mapped_normal(const Interaction& it) const override {
        const Color c = normals_->eval(it.uv);
        return Vec3(2.f * c.x - 1.f, 2.f * c.y - 1.f, 2.f * c.z - 1.f);
    }

private:
    std::shared_ptr<const Texture> normals_;
};

class BumpMapBsdf final : public FrameMapBsdf {
public:
    BumpMapBsdf(std::unique_ptr<Bsdf> nested, bool flip, bool shadowing, std::shared_ptr<const Texture> height,
                float scale)
        : FrameMapBsdf(std::move(nested), flip, shadowing), height_(std::move(height)), scale_(scale) {}

protected:
    Vec3 mapped_normal(const Interaction& it) const override {
        const Vec2 g = height_->eval_1_grad(it.uv);
        const Vec3& ns = it.sh.n;
        const Vec3 du = it.dp_du + ns * (scale_ * g.x - dot(ns, it.dp_du));
        const Vec3 dv = it.dp_dv + ns * (scale_ * g.y - dot(ns, it.dp_dv));
        Vec3 n = cross(du, dv);
        if (dot(it.n, n) < 0.f) n = -n;
        return it.sh.to_local(n);
    }
    // Mitsuba 3.9.1's bumpmap seeds its tangent with dp_du as it stands, in
    // world coordinates, beside the local n' (its normalmap uses e_x);
    // kept, since it sets the axes of a nested anisotropic BSDF (measured
    // against mitsuba.load_dict: with e_x its rough conductor differs by up
    // to 200 times, with dp_du within 3e-6; tests/test_normalmap.py).
    Vec3 tangent_seed(const Interaction& it) const override { return it.dp_du; }

private:
    std::shared_ptr<const Texture> height_;
    float scale_;
};

}  // namespace

// ---------------------------------------------------------------------------
// bsdf_util.h

namespace bsdf_util {

void fail(const BsdfDesc& d, const std::string& param, const std::string& why) {
    throw std::invalid_argument("bsdf '" + d.id + "' (type '" + d.type + "'): parameter '" + param + "' " + why);
}

void check_color(const BsdfDesc& d, const char* name, const Color& c) {
    if (!is_finite(c) || min_component(c) < 0.f) fail(d, name, "must be finite and non-negative");
}

TexturedColor textured(const BsdfDesc& d, const char* name, const Color& plain) {
    TexturedColor c(plain);
    auto it = d.textures.find(name);
    if (it == d.textures.end()) {
        check_color(d, name, plain);
        return c;
    }
    try {
        c.texture = make_texture(it->second);
    } catch (const std::invalid_argument& e) {
        fail(d, name, std::string("has a bad texture: ") + e.what());
    }
    return c;
}

std::shared_ptr<const Texture> texture_of(const BsdfDesc& d, const char* name) {
    auto it = d.textures.find(name);
    if (it == d.textures.end()) return nullptr;
    try {
        return make_texture(it->second);
    } catch (const std::invalid_argument& e) {
        fail(d, name, std::string("has a bad texture: ") + e.what());
    }
}

void check_textured_names(const BsdfDesc& d, std::initializer_list<const char*> allowed) {
    for (const auto& [name, tex] : d.textures) {
        bool ok = false;
        for (const char* a : allowed) ok = ok || name == a;
        if (!ok) fail(d, name, "cannot take a texture (texture type '" + tex.type + "')");
    }
}

}  // namespace bsdf_util

std::unique_ptr<Bsdf> make_bsdf(const BsdfDesc& d) {
    if (d.type == "principled" || d.type == "principledthin") return make_principled(d);
    if (d.type == "blendbsdf") {
        check_textured_names(d, {"weight"});
        if (d.nested.size() != 2) fail(d, "nested", "must hold 2 BSDFs, got " + std::to_string(d.nested.size()));
        auto it = d.floats.find("weight");
        if (it == d.floats.end()) fail(d, "weight", "is missing (Mitsuba 3 requires it)");
        TexturedFloat weight(it->second);
        if (!std::isfinite(weight.value)) fail(d, "weight", "must be finite");
        weight.texture = texture_of(d, "weight");
        std::unique_ptr<Bsdf> b0 = make_bsdf(d.nested[0]), b1 = make_bsdf(d.nested[1]);
        // A shadow ray through a null lobe has no uv to read the weight at.
        if (weight.textured() && ((b0->flags() | b1->flags()) & kNull))
            fail(d, "weight", "cannot be a texture when a nested BSDF has a null lobe (null, thindielectric)");
        return std::make_unique<BlendBsdf>(std::move(weight), std::move(b0), std::move(b1));
    }
    if (d.type == "diffuse") {
        check_textured_names(d, {"reflectance"});
        return std::make_unique<DiffuseBsdf>(textured(d, "reflectance", d.reflectance));
    }
    if (d.type == "conductor" || d.type == "roughconductor") {
        if (d.type == "conductor")
            check_textured_names(d, {"specular_reflectance"});
        else
            check_textured_names(d, {"specular_reflectance", "alpha_u", "alpha_v"});
        check_color(d, "eta", d.eta);
        check_color(d, "k", d.k);
        TexturedColor spec = textured(d, "specular_reflectance", d.specular_reflectance);
        if (d.type == "conductor") return std::make_unique<ConductorBsdf>(d.eta, d.k, std::move(spec));
        return std::make_unique<RoughConductorBsdf>(make_distribution(d), d.eta, d.k, std::move(spec),
                                                    texture_of(d, "alpha_u"), texture_of(d, "alpha_v"));
    }
    if (d.type != "plastic" && d.type != "roughplastic" && d.type != "mask" && d.type != "normalmap" &&
        d.type != "bumpmap")
        check_textured_names(d, {});
    if (d.type == "dielectric" || d.type == "roughdielectric" || d.type == "thindielectric") {
        const float eta = relative_ior(d);
        check_color(d, "specular_reflectance", d.specular_reflectance);
        check_color(d, "specular_transmittance", d.specular_transmittance);
        if (d.type == "dielectric")
            return std::make_unique<DielectricBsdf>(eta, d.specular_reflectance, d.specular_transmittance);
        if (d.type == "thindielectric")
            return std::make_unique<ThinDielectricBsdf>(eta, d.specular_reflectance, d.specular_transmittance);
        if (d.int_ior == d.ext_ior)
            fail(d, "int_ior", "must differ from ext_ior (index-matched rough interface; use dielectric or null)");
        return std::make_unique<RoughDielectricBsdf>(make_distribution(d), eta, d.specular_reflectance,
                                                     d.specular_transmittance);
    }
    if (d.type == "plastic") {
        const float eta = relative_ior(d);
        check_textured_names(d, {"diffuse_reflectance"});
        check_color(d, "specular_reflectance", d.specular_reflectance);
        return std::make_unique<PlasticBsdf>(eta, textured(d, "diffuse_reflectance", d.diffuse_reflectance),
                                             d.specular_reflectance, d.nonlinear);
    }
    if (d.type == "roughplastic") {
        const float eta = relative_ior(d);
        if (d.int_ior == d.ext_ior) fail(d, "int_ior", "must differ from ext_ior (as in Mitsuba's roughplastic)");
        check_textured_names(d, {"diffuse_reflectance"});
        check_color(d, "specular_reflectance", d.specular_reflectance);
        const MicrofacetDistribution distr = make_distribution(d);
        if (d.alpha_u != d.alpha_v) fail(d, "alpha_u", "must equal alpha_v (roughplastic is isotropic, as in Mitsuba)");
        return std::make_unique<RoughPlasticBsdf>(distr, eta, textured(d, "diffuse_reflectance", d.diffuse_reflectance),
                                                  d.specular_reflectance, d.nonlinear);
    }
    if (d.type == "twosided") {
        if (d.nested.empty() || d.nested.size() > 2)
            fail(d, "nested", "must hold 1 or 2 BSDFs, got " + std::to_string(d.nested.size()));
        std::unique_ptr<Bsdf> front = make_bsdf(d.nested[0]);
        std::unique_ptr<Bsdf> back = d.nested.size() == 2 ? make_bsdf(d.nested[1]) : nullptr;
        if ((front->flags() & kTransmission) || (back && (back->flags() & kTransmission)))
            fail(d, "nested", "must not transmit light (only reflective BSDFs can be made two-sided)");
        // The map perturbs the hit's frame before twosided mirrors wi, the
        // other order from Mitsuba's: refused rather than rendered otherwise.
        if (front->perturbs_frame() || (back && back->perturbs_frame()))
            fail(d, "nested", "must not be a normalmap or bumpmap (put the map around the twosided BSDF)");
        return std::make_unique<TwoSidedBsdf>(std::move(front), std::move(back));
    }
    if (d.type == "null") return std::make_unique<NullBsdf>();
    if (d.type == "mask" || d.type == "normalmap" || d.type == "bumpmap") {
        if (d.nested.size() != 1)
            fail(d, "nested", "must hold exactly one BSDF, got " + std::to_string(d.nested.size()));
        std::unique_ptr<Bsdf> nested = make_bsdf(d.nested[0]);
        if (d.type != "mask" && nested->perturbs_frame())
            fail(d, "nested", "must not be another normalmap or bumpmap (one map per surface)");
        if (d.type == "mask") {
            check_textured_names(d, {"opacity"});
            if (!std::isfinite(d.opacity)) fail(d, "opacity", "must be finite");
            return std::make_unique<MaskBsdf>(std::move(nested), d.opacity, texture_of(d, "opacity"));
        }
        if (d.type == "normalmap") {
            check_textured_names(d, {"normalmap"});
            auto normals = texture_of(d, "normalmap");
            if (!normals) fail(d, "normalmap", "is missing (a texture of tangent-space normals)");
            return std::make_unique<NormalMapBsdf>(std::move(nested), d.flip_invalid_normals, d.use_shadowing_function,
                                                   std::move(normals));
        }
        // bumpmap: one nested texture, whatever its name (as Mitsuba).
        if (d.textures.size() != 1)
            fail(d, "texture",
                 "must be exactly one nested texture (the height field), got " + std::to_string(d.textures.size()));
        if (!std::isfinite(d.scale)) fail(d, "scale", "must be finite");
        auto height = texture_of(d, d.textures.begin()->first.c_str());
        return std::make_unique<BumpMapBsdf>(std::move(nested), d.flip_invalid_normals, d.use_shadowing_function,
                                             std::move(height), d.scale);
    }
    throw std::invalid_argument("bsdf '" + d.id + "': unknown type '" + d.type + "'");
}

}  // namespace rm
