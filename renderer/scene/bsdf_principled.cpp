// principled and principledthin: the Disney BSDF as Mitsuba 3 implements it
// (src/bsdfs/principled.cpp, principledthin.cpp, principledhelpers.h), term
// for term, so that our images and Mitsuba's agree per pixel. The model is
// Burley 2012, "Physically Based Shading at Disney" (SIGGRAPH course notes)
// and Burley 2015, "Extending the Disney BRDF to a BSDF with Integrated
// Subsurface Scattering" (SIGGRAPH course notes); the microfacet terms are
// Walter et al. 2007, "Microfacet Models for Refraction through Rough
// Surfaces". Where Mitsuba departs from the papers, we follow Mitsuba (the
// comments say where).
//
// Parameters (BsdfDesc::base_color and BsdfDesc::floats by Mitsuba's names,
// defaults filled in by the loader; [default]; "tex": may be a texture,
// read with eval_1 except base_color):
//  principled      base_color [0.5] tex, roughness [0.5] tex, anisotropic [0]
//                  tex, metallic [0] tex, spec_trans [0] tex, spec_tint [0]
//                  tex, sheen [0] tex, sheen_tint [0] tex, flatness [0] tex,
//                  clearcoat [0] tex, clearcoat_gloss [0] tex, eta (the
//                  interior / exterior IOR; the loader derives it from
//                  `specular` [0.5] when eta is not given, eta = 2 / (1 -
//                  sqrt(0.08 specular)) - 1, Burley 2015 sec. 5.1, and
//                  applies Mitsuba's guards of a transmitting eta of 1),
//                  main_specular_sampling_rate [1], clearcoat_sampling_rate
//                  [1], diffuse_reflectance_sampling_rate [1].
//  principledthin  base_color, roughness, anisotropic, spec_trans, spec_tint,
//                  sheen, sheen_tint, flatness as above, eta [1.5] tex,
//                  diff_trans [0] tex (0 .. 2: the share of the diffuse
//                  energy transmitted), specular_reflectance_sampling_rate,
//                  specular_transmittance_sampling_rate,
//                  diffuse_reflectance_sampling_rate,
//                  diffuse_transmittance_sampling_rate [1 each].
// Values outside Mitsuba's documented ranges ([0, 1]; diff_trans [0, 2]; eta
// > 0; sampling rates >= 0) are refused, plain or as a texture's extremes.
// As Mitsuba's get_flag, a lobe exists when its parameter is a texture or
// non-zero: principled's glossy transmission (spec_trans), the anisotropic
// frame (anisotropic).
//
// The lobes (eval includes |cos theta_o|; wh the half vector, oriented up):
//  principled (one object, an interior behind the normal):
//   - diffuse (Burley 2015, eqs. 4 and 5: f_diff (1 - F_i / 2)(1 - F_o / 2)
//     and retro-reflection R_R (F_o + F_i + F_o F_i (R_R - 1)), R_R = 2
//     roughness cos^2 theta_d), blended towards Hanrahan-Krueger's fake
//     subsurface by flatness (Burley 2012, sec. 5.3) and weighted by
//     (1 - metallic)(1 - spec_trans); front side only;
//   - sheen: sheen F_D (lerp(1, tint, sheen_tint)) (Burley 2012, sec. 5.4),
//     where the diffuse lobe is;
//   - main specular reflection: GGX (Walter eq. 20) with Mitsuba's blended
//     Fresnel: (1 - metallic)(1 - spec_tint) F_dielectric + Schlick terms of
//     metallic (F0 = base_color) and spec_tint (F0 = tint R0(eta)); from
//     inside, (1 - metallic) spec_trans F_dielectric;
//   - main specular transmission: sqrt(base_color) (Burley 2015, sec. 4.2)
//     (1 - metallic) spec_trans times Walter's eq. 21, with the 1 / eta^2 of
//     radiance in Radiance mode (non-reciprocal, as a refraction must be);
//   - clearcoat: clearcoat / 4 F_Schlick(0.04) D_GTR1 G_GGX(0.25) |cos o|,
//     D_GTR1 of alpha lerp(0.1, 0.001, clearcoat_gloss) (Burley 2012, eq. 4,
//     sec. B.2); Mitsuba's form, without the paper's 1 / (4 cos_i cos_o).
//  principledthin (a sheet: both sides alike, no interior; eta only bends
//  the roughness): diffuse and sheen as above, weighted by (1 - spec_trans)
//  (1 - diff_trans / 2); diffuse transmission (1 - spec_trans) diff_trans / 2
//  base_color / pi; specular reflection spec_trans F_thin D G / (4 cos_i),
//  F_thin = lerp(F_dielectric, F_Schlick(tint R0(eta)), spec_tint); specular
//  transmission spec_trans base_color (1 - F) D' G' / (4 cos_i) with the
//  lobe mirrored through the sheet and the roughness scaled by
//  (0.65 eta - 0.35) (Burley 2015, sec. 4.3, fig. 15). Mitsuba's side
//  checks of that lobe's microfacet (mac_mic_compatibility, G1's chi) are
//  made with the unmirrored wo, which makes it non-reciprocal for some pairs
//  (one way 0, the other not; docs/principled.md has the measurements on
//  Mitsuba itself); Radiance mode is Mitsuba's f(wi, wo), Importance mode
//  its transpose f(wo, wi) (Veach 1997, eq. 5.15), so that light and camera
//  paths estimate the same image. The other lobes are reciprocal.
// Roughness alpha = max(1e-3, roughness^2), anisotropic alpha_x = alpha /
// sqrt(1 - 0.9 anisotropic), alpha_y = alpha sqrt(...) (Burley 2012, sec. B.2).
// Sampling (as Mitsuba): a lobe picked with probabilities from the sampling
// rates and the lobe weights (GGX visible normals, GTR1's D cos, cosine
// hemispheres), then pdf = the mixture's pdf and weight = eval / pdf.
#include "scene/bsdf_principled.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "core/warp.h"
#include "scene/bsdf_util.h"
#include "scene/fresnel.h"
#include "scene/microfacet.h"
#include "scene/texture.h"

namespace rm {

namespace {

using namespace bsdf_util;

// ---------------------------------------------------------------------------
// Parameters

enum Param : int {
    kRoughness,
    kAnisotropic,
    kMetallic,
    kSpecTrans,
    kSpecTint,
    kSheen,
    kSheenTint,
    kFlatness,
    kClearcoat,
    kClearcoatGloss,
    kEta,
    kDiffTrans,
    kNumParams
};
constexpr std::array<const char*, kNumParams> kParamNames = {
    "roughness",  "anisotropic", "metallic",  "spec_trans",      "spec_tint", "sheen",
    "sheen_tint", "flatness",    "clearcoat", "clearcoat_gloss", "eta",       "diff_trans"};

// The parameters at one uv.
struct Values {
    Color base{0.5f};
    std::array<float, kNumParams> v{};
    float operator[](Param p) const { return v[size_t(p)]; }
};

// The smallest and largest values a texture can give (checkerboard colours'
// channels, bitmap texels: eval, eval_1 and their interpolation stay
// within), or nothing known (lo > hi) for other types.
std::pair<float, float> texture_range(const TextureDesc& t) {
    if (t.type == "checkerboard")
        return {std::min(min_component(t.color0), min_component(t.color1)),
                std::max(max_component(t.color0), max_component(t.color1))};
    if (t.type == "bitmap" && !t.data.empty()) {
        const auto [lo, hi] = std::minmax_element(t.data.begin(), t.data.end());
        return {*lo, *hi};
    }
    return {1.f, 0.f};
}

std::string fmt(float x) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", double(x));
    return buf;
}

// A parameter's plain value, or its texture's range, must lie in [lo, hi]
// (lo_open: > lo).
void check_range(const BsdfDesc& d, const char* name, float value_lo, float value_hi, float lo, float hi,
                 bool lo_open = false) {
    const std::string range = (lo_open ? "(" : "[") + fmt(lo) + ", " + fmt(hi) + "]";
    auto it = d.textures.find(name);
    if (it != d.textures.end()) {
        const auto [t_lo, t_hi] = texture_range(it->second);
        if (t_lo <= t_hi && (t_lo < lo || (lo_open && t_lo <= lo) || t_hi > hi))
            fail(d, name, "has a texture with values in [" + fmt(t_lo) + ", " + fmt(t_hi) + "], outside " + range);
        return;
    }
    if (!std::isfinite(value_lo) || !std::isfinite(value_hi) || value_lo < lo || (lo_open && value_lo <= lo) ||
        value_hi > hi)
        fail(d, name, "must lie in " + range);
}

// Mitsuba's schlick_weight: (1 - cos)^5, clamped.
inline float schlick_weight(float cos_theta) {
    const float m = clamp(1.f - cos_theta, 0.f, 1.f);
    return sqr(sqr(m)) * m;
}

// Mitsuba's calc_schlick: Schlick's approximation F0 + (1 - F0)(1 - cos)^5
// (Schlick 1994, "An Inexpensive BRDF Model for Physically-based
// Rendering", eq. 24), with the transmitted angle's cosine where the
// relative IOR along the ray is below 1 (as principledhelpers.h).
template <typename T>
T schlick(const T& f0, float cos_theta_i, float eta) {
    const bool outside = cos_theta_i >= 0.f;
    const float eta_it = outside ? eta : 1.f / eta, eta_ti = outside ? 1.f / eta : eta;
    const float cos_t = safe_sqrt(1.f - (1.f - cos_theta_i * cos_theta_i) * sqr(eta_ti));
    const float w = schlick_weight(eta_it > 1.f ? std::fabs(cos_theta_i) : cos_t);
    return f0 + (T(1.f) - f0) * w;
}

// F0 of a dielectric, ((eta - 1) / (eta + 1))^2 (Schlick 1994, eq. 24).
inline float schlick_r0(float eta) { return sqr((eta - 1.f) / (eta + 1.f)); }

// base_color / luminance: the tint of spec_tint and sheen_tint (Burley 2012, sec. B.2).
inline Color tint_of(const Color& base) {
    const float lum = luminance(base);
    return lum > 0.f ? base / lum : Color(1.f);
}

// Mitsuba's mac_mic_compatibility: wi in front of the microfacet m turned to
// wi's side, and wo in front of it (reflection) or behind it (transmission).
inline bool mac_mic(const Vec3& m, const Vec3& wi, const Vec3& wo, float cos_i, bool reflection) {
    const Vec3 ms = mulsign(m, cos_i);
    return dot(wi, ms) > 0.f && (reflection ? dot(wo, ms) > 0.f : dot(wo, ms) < 0.f);
}

// The main lobes' GGX distribution, visible normals sampled (Burley 2012,
// sec. B.2, with Mitsuba's floor of 1e-3 on alpha: calc_dist_params).
MicrofacetDistribution ggx(float anisotropic, float roughness) {
    const float r2 = sqr(roughness);
    const float aspect = std::sqrt(1.f - 0.9f * anisotropic);
    return MicrofacetDistribution(MicrofacetType::GGX, std::max(1e-3f, r2 / aspect), std::max(1e-3f, r2 * aspect),
                                  true);
}

// GTR1, the clearcoat's normal distribution (Burley 2012, eq. 4 with
// gamma = 1): D = (alpha^2 - 1) / (pi log(alpha^2) (1 + (alpha^2 - 1) cos^2)),
// sampled in proportion to D cos (ibid., sec. B.2); Mitsuba's GTR1Isotropic.
class Gtr1 {
public:
    explicit Gtr1(float alpha) : a2_(sqr(alpha)) {}
    float D(const Vec3& m) const {
        const float r = (a2_ - 1.f) / (kPi * std::log(a2_) * (1.f + (a2_ - 1.f) * sqr(m.z)));
        return r * m.z > 1e-20f ? r : 0.f;
    }
    float pdf(const Vec3& m) const { return m.z < 0.f ? 0.f : m.z * D(m); }
    Vec3 sample(Vec2 u) const {
        const float phi = 2.f * kPi * u.x;
        const float cos2 = (1.f - std::pow(a2_, 1.f - u.y)) / (1.f - a2_);
        const float sin_t = safe_sqrt(1.f - cos2), cos_t = safe_sqrt(cos2);
        return {std::cos(phi) * sin_t, std::sin(phi) * sin_t, cos_t};
    }

private:
    float a2_;
};

// The clearcoat's alpha, lerp(0.1, 0.001, clearcoat_gloss) (Burley 2012, sec. B.2).
inline float clearcoat_alpha(float gloss) { return 0.1f * (1.f - gloss) + 0.001f * gloss; }

// The diffuse base shared by both BSDFs, per unit of base_color / pi:
// Burley 2015, eqs. 4 and 5, blended by flatness towards Burley 2012's
// Hanrahan-Krueger-like f_ss (sec. 5.3); |cos_i|, |cos_o|, cos_d = wo.wh.
float disney_diffuse(float cos_i, float cos_o, float cos_d, float roughness, float flatness) {
    const float fo = schlick_weight(cos_o), fi = schlick_weight(cos_i);
    const float f_diff = (1.f - 0.5f * fi) * (1.f - 0.5f * fo);
    const float rr = 2.f * roughness * sqr(cos_d);
    const float f_retro = rr * (fo + fi + fo * fi * (rr - 1.f));
    if (flatness == 0.f) return f_diff + f_retro;
    const float fss90 = 0.5f * rr;
    const float fss = (1.f + (fss90 - 1.f) * fo) * (1.f + (fss90 - 1.f) * fi);
    const float f_ss = 1.25f * (fss * (1.f / (cos_o + cos_i) - 0.5f) + 0.5f);
    return (f_diff + f_retro) * (1.f - flatness) + f_ss * flatness;
}

// The sheen per unit of its lobe's weight, without |cos_o| (Burley 2012, sec. 5.4).
Color sheen_term(const Values& v, float cos_d) {
    const Color c = Color(1.f - v[kSheenTint]) + tint_of(v.base) * v[kSheenTint];
    return c * (v[kSheen] * schlick_weight(std::fabs(cos_d)));
}

// ---------------------------------------------------------------------------
// The parameters of both BSDFs, textured or plain.

class PrincipledCommon : public Bsdf {
protected:
    PrincipledCommon(const BsdfDesc& d, std::initializer_list<Param> params) {
        base_ = bsdf_util::textured(d, "base_color", d.base_color);
        check_range(d, "base_color", min_component(d.base_color), max_component(d.base_color), 0.f, 1.f);
        bool any_texture = base_.textured();
        for (Param p : params) {
            const char* name = kParamNames[size_t(p)];
            auto it = d.floats.find(name);
            if (it == d.floats.end()) fail(d, name, "is missing (the loader fills in Mitsuba's default)");
            TexturedFloat& t = params_[size_t(p)];
            t.value = it->second;
            t.texture = texture_of(d, name);
            if (p == kEta)
                check_range(d, name, t.value, t.value, 0.f, std::numeric_limits<float>::max(), true);
            else
                check_range(d, name, t.value, t.value, 0.f, p == kDiffTrans ? 2.f : 1.f);
            any_texture = any_texture || t.textured();
            has_[size_t(p)] = t.textured() || t.value != 0.f;
        }
        textured_ = any_texture;
        anisotropic_ = has(kAnisotropic);
    }

    // Mitsuba's get_flag: the parameter is a texture or non-zero.
    bool has(Param p) const { return has_[size_t(p)]; }
    Values at(const SurfaceUv& uv) const {
        Values v;
        v.base = base_.eval(uv);
        for (size_t i = 0; i < kNumParams; ++i) v.v[i] = params_[i].eval(uv);
        return v;
    }
    // A sampling rate: finite and >= 0.
    static float rate(const BsdfDesc& d, const char* name) {
        auto it = d.floats.find(name);
        if (it == d.floats.end()) fail(d, name, "is missing (the loader fills in Mitsuba's default)");
        if (!std::isfinite(it->second) || it->second < 0.f) fail(d, name, "must be finite and >= 0");
        return it->second;
    }

private:
    TexturedColor base_;
    std::array<TexturedFloat, kNumParams> params_{};  // those not given stay 0
    std::array<bool, kNumParams> has_{};
};

// ---------------------------------------------------------------------------
// principled

class PrincipledBsdf final : public PrincipledCommon {
public:
    explicit PrincipledBsdf(const BsdfDesc& d)
        : PrincipledCommon(d, {kRoughness, kAnisotropic, kMetallic, kSpecTrans, kSpecTint, kSheen, kSheenTint,
                               kFlatness, kClearcoat, kClearcoatGloss, kEta}),
          spec_rate_(rate(d, "main_specular_sampling_rate")),
          clearcoat_rate_(rate(d, "clearcoat_sampling_rate")),
          diffuse_rate_(rate(d, "diffuse_reflectance_sampling_rate")),
          eta_(d.floats.at("eta")) {
        flags_ = kDiffuseReflection | kGlossyReflection | (has(kSpecTrans) ? kGlossyTransmission : 0u);
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        BsdfSample bs;
        const float cos_i = wi.z;
        if (cos_i == 0.f || !std::isfinite(cos_i)) return bs;  // perfectly grazing
        const Values v = at(ctx.uv);
        const Weights w = weights(v);
        const bool front = cos_i > 0.f;
        if (!front && !(w.bsdf > 0.f)) return bs;  // no transmission: nothing from inside

        // The main lobes' normal, sampled whichever lobe is picked: its
        // Fresnel factor splits reflection from transmission (as Mitsuba).
        const MicrofacetDistribution distr = ggx(v[kAnisotropic], v[kRoughness]);
        const Vec3 m = distr.sample(mulsign(wi, cos_i), u2).m;
        const FresnelDielectric fr = fresnel_dielectric(dot(wi, m), eta_);
        const Probabilities p = probabilities(v, w, front, fr.F);

        // Mitsuba's order on [0, 1): diffuse, clearcoat, transmission, reflection.
        if (u1 < p.diffuse) {
            bs.wo = warp::square_to_cosine_hemisphere(u2);
            bs.sampled_flags = kDiffuseReflection;
            if (!(bs.wo.z * cos_i > 0.f)) return BsdfSample{};
        } else if (u1 < p.diffuse + p.clearcoat) {
            const Vec3 mc = Gtr1(clearcoat_alpha(v[kClearcoatGloss])).sample(u2);
            bs.wo = reflect(wi, mc);
            bs.sampled_flags = kGlossyReflection;
            if (!(bs.wo.z * cos_i > 0.f) || !mac_mic(mc, wi, bs.wo, cos_i, true)) return BsdfSample{};
        } else if (u1 < p.diffuse + p.clearcoat + p.spec_trans) {
            bs.wo = refract(wi, m, fr.cos_theta_t, fr.eta_ti);
            bs.sampled_flags = kGlossyTransmission;
            bs.eta = fr.eta_it;
            if (!(bs.wo.z * cos_i < 0.f) || !mac_mic(m, wi, bs.wo, cos_i, false)) return BsdfSample{};
        } else {
            bs.wo = reflect(wi, m);
            bs.sampled_flags = kGlossyReflection;
            if (!(bs.wo.z * cos_i > 0.f) || !mac_mic(m, wi, bs.wo, cos_i, true)) return BsdfSample{};
        }
        // The mixture's density and value, so that weight = eval / pdf exactly.
        Color value;
        eval_pdf(ctx, v, wi, bs.wo, &value, &bs.pdf_w);
        if (!(bs.pdf_w > 0.f)) return BsdfSample{};
        bs.weight = value / bs.pdf_w;
        return sanitize(bs);
    }

    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        Color value;
        float pdf;
        eval_pdf(ctx, at(ctx.uv), wi, wo, &value, &pdf);
        return value;
    }
    float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        Color value;
        float pdf;
        eval_pdf(ctx, at(ctx.uv), wi, wo, &value, &pdf);
        return pdf;
    }

private:
    struct Weights {
        float brdf, bsdf;  // of the reflecting base and of the transmitting dielectric
    };
    Weights weights(const Values& v) const {
        const float m = v[kMetallic], t = v[kSpecTrans];
        return {(1.f - m) * (1.f - t), has(kSpecTrans) ? (1.f - m) * t : 0.f};
    }

    struct Probabilities {
        float diffuse = 0.f, clearcoat = 0.f, spec_trans = 0.f, spec_reflect = 0.f;
    };
    // Mitsuba's lobe-selection probabilities, F = F_dielectric(wi.m). In
    // front the diffuse and clearcoat shares do not depend on F (the
    // specular pair sums to spec_rate), so the choice among all four is
    // consistent with pdf(), which uses F at the half vector.
    Probabilities probabilities(const Values& v, const Weights& w, bool front, float F) const {
        Probabilities p;
        if (front) {
            p.spec_reflect = spec_rate_ * (1.f - w.bsdf * (1.f - F));
            p.spec_trans = has(kSpecTrans) ? spec_rate_ * w.bsdf * (1.f - F) : 0.f;
            p.clearcoat = has(kClearcoat) ? 0.25f * v[kClearcoat] * clearcoat_rate_ : 0.f;
            p.diffuse = w.brdf * diffuse_rate_;
        } else {
            p.spec_reflect = F;
            p.spec_trans = has(kSpecTrans) ? 1.f - F : 0.f;
        }
        const float total = p.diffuse + p.clearcoat + p.spec_trans + p.spec_reflect;
        if (!(total > 0.f)) return Probabilities{};
        const float inv = 1.f / total;
        p.diffuse *= inv;
        p.clearcoat *= inv;
        p.spec_trans *= inv;
        p.spec_reflect *= inv;
        return p;
    }

    // Mitsuba's principled_fresnel: metallic and tinted dielectric by Schlick,
    // the rest by the exact dielectric F; from inside the dielectric F alone.
    Color fresnel(const Values& v, const Weights& w, float F, float cos_ih, bool front) const {
        if (!front) return Color(w.bsdf * F);
        const float metallic = v[kMetallic], tint = v[kSpecTint];
        Color f_schlick(0.f);
        if (has(kMetallic)) f_schlick += schlick(v.base, cos_ih, eta_) * metallic;
        if (has(kSpecTint)) {
            const float eta_it = cos_ih >= 0.f ? eta_ : 1.f / eta_;
            f_schlick += schlick(tint_of(v.base) * schlick_r0(eta_it), cos_ih, eta_) * ((1.f - metallic) * tint);
        }
        return Color((1.f - metallic) * (1.f - tint) * F) + f_schlick;
    }

    void eval_pdf(const BsdfContext& ctx, const Values& v, const Vec3& wi, const Vec3& wo, Color* value,
                  float* pdf) const {
        *value = Color(0.f);
        *pdf = 0.f;
        const float cos_i = wi.z, cos_o = wo.z;
        if (cos_i == 0.f || !std::isfinite(cos_i)) return;
        const bool reflect = cos_i * cos_o > 0.f, refract = cos_i * cos_o < 0.f;
        if (!reflect && !refract) return;
        const bool front = cos_i > 0.f;
        const Weights w = weights(v);
        // Relative IOR across the interface in the direction wi -> wo.
        const float eta_path = front ? eta_ : 1.f / eta_;

        // Generalised half vector (Walter et al. 2007, eqs. 13 and 16), up.
        Vec3 wh = reflect ? wi + wo : wi + wo * eta_path;
        const float len = length(wh);
        if (!(len > 0.f) || !std::isfinite(len)) return;
        wh = mulsign(wh / len, wh.z);
        const float wi_h = dot(wi, wh), wo_h = dot(wo, wh);
        const float F = fresnel_dielectric(wi_h, eta_).F;
        const bool refl_ok = reflect && mac_mic(wh, wi, wo, cos_i, true);
        const bool refr_ok = refract && mac_mic(wh, wi, wo, cos_i, false);
        const MicrofacetDistribution distr = ggx(v[kAnisotropic], v[kRoughness]);
        const float D = distr.D(wh), G = distr.G(wi, wo, wh);

        Color f(0.f);
        // Main specular reflection (Walter eq. 20, times |cos_o|).
        if (refl_ok && F > 0.f) f += fresnel(v, w, F, wi_h, front) * (D * G / (4.f * std::fabs(cos_i)));
        // Main specular transmission (Walter eq. 21, times |cos_o|), radiance
        // compressed by 1 / eta^2 (Veach 1997, sec. 5.2), tinted sqrt(base)
        // (Burley 2015, sec. 4.2).
        if (has(kSpecTrans) && w.bsdf > 0.f && refr_ok && F < 1.f) {
            const float scale = ctx.mode == TransportMode::Radiance ? 1.f / sqr(eta_path) : 1.f;
            const float ft = std::fabs(scale * (1.f - F) * D * G * sqr(eta_path) * wi_h * wo_h /
                                       (cos_i * sqr(wi_h + eta_path * wo_h)));
            f += Color(std::sqrt(v.base.x), std::sqrt(v.base.y), std::sqrt(v.base.z)) * (w.bsdf * ft);
        }
        // Clearcoat (Burley 2012, sec. B.2; Mitsuba's form, see the file head).
        if (has(kClearcoat) && v[kClearcoat] > 0.f && refl_ok && front) {
            const float fcc = schlick(0.04f, wi_h, eta_);
            const float dcc = Gtr1(clearcoat_alpha(v[kClearcoatGloss])).D(wh);
            const float gcc = clearcoat_masking().G(wi, wo, wh);
            f += Color(0.25f * v[kClearcoat] * fcc * dcc * gcc * std::fabs(cos_o));
        }
        // Diffuse, retro-reflection, fake subsurface and sheen, in front.
        if (front && reflect && w.brdf > 0.f) {
            const float cos_d = dot(wh, wo);
            f += v.base * (w.brdf * std::fabs(cos_o) * kInvPi *
                           disney_diffuse(std::fabs(cos_i), std::fabs(cos_o), cos_d, v[kRoughness], v[kFlatness]));
            if (has(kSheen) && v[kSheen] > 0.f && 1.f - v[kMetallic] > 0.f)
                f += sheen_term(v, cos_d) * ((1.f - v[kMetallic]) * std::fabs(cos_o));
        }
        *value = finite_or_zero(f);

        // The mixture's pdf: each lobe's density times its probability.
        const Probabilities p = probabilities(v, w, front, F);
        // |d wh / d wo| (Walter eqs. 14 and 17).
        const float dwh_dwo =
            std::fabs(reflect ? 1.f / (4.f * wo_h) : sqr(eta_path) * wo_h / sqr(wi_h + eta_path * wo_h));
        const Vec3 wi_up = mulsign(wi, cos_i);
        float density = 0.f;
        if (refl_ok) density += p.spec_reflect * distr.pdf_w(wi_up, wh) * dwh_dwo;
        if (reflect) density += p.diffuse * warp::square_to_cosine_hemisphere_pdf_w(wo);
        if (refr_ok) density += p.spec_trans * distr.pdf_w(wi_up, wh) * dwh_dwo;
        if (refl_ok && p.clearcoat > 0.f)
            density += p.clearcoat * Gtr1(clearcoat_alpha(v[kClearcoatGloss])).pdf(wh) * dwh_dwo;
        *pdf = finite_or_zero(density);
    }

    // The clearcoat's masking: GGX of alpha 0.25 (Burley 2012, sec. B.2;
    // Mitsuba's clearcoat_G / smith_ggx1).
    static const MicrofacetDistribution& clearcoat_masking() {
        static const MicrofacetDistribution d(MicrofacetType::GGX, 0.25f, 0.25f, true);
        return d;
    }

    float spec_rate_, clearcoat_rate_, diffuse_rate_;
    float eta_;
};

// ---------------------------------------------------------------------------
// principledthin: evaluated with wi turned to the front (the sheet has no
// inside) and wo turned with it.

class PrincipledThinBsdf final : public PrincipledCommon {
public:
    explicit PrincipledThinBsdf(const BsdfDesc& d)
        : PrincipledCommon(
              d, {kRoughness, kAnisotropic, kSpecTrans, kSpecTint, kSheen, kSheenTint, kFlatness, kEta, kDiffTrans}),
          spec_reflect_rate_(rate(d, "specular_reflectance_sampling_rate")),
          spec_trans_rate_(rate(d, "specular_transmittance_sampling_rate")),
          diffuse_reflect_rate_(rate(d, "diffuse_reflectance_sampling_rate")),
          diffuse_trans_rate_(rate(d, "diffuse_transmittance_sampling_rate")) {
        // As Mitsuba: the diffuse transmission lobe is declared even when
        // diff_trans is 0 (so, as there, twosided refuses to nest it).
        flags_ = kDiffuseReflection | kDiffuseTransmission | kGlossyReflection |
                 (has(kSpecTrans) ? kGlossyTransmission : 0u);
    }

    BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const override {
        BsdfSample bs;
        const float cos_i = wi.z;
        if (cos_i == 0.f || !std::isfinite(cos_i)) return bs;
        const Values v = at(ctx.uv);
        const Vec3 wf = mulsign(wi, cos_i);  // wi on the front
        const Probabilities p = probabilities(v);

        // Mitsuba's order on [0, 1): specular reflection, specular
        // transmission, diffuse reflection, diffuse transmission.
        Vec3 wo;
        if (u1 < p.spec_reflect) {
            const Vec3 m = ggx(v[kAnisotropic], v[kRoughness]).sample(wf, u2).m;
            wo = reflect(wf, m);
            bs.sampled_flags = kGlossyReflection;
            if (!(wo.z > 0.f) || !mac_mic(m, wf, wo, wf.z, true)) return BsdfSample{};
        } else if (u1 < p.spec_reflect + p.spec_trans) {
            // Reflected on the roughness-scaled lobe, then mirrored through
            // the sheet: a thin slab does not bend the ray.
            const Vec3 m = trans_distribution(v).sample(wf, u2).m;
            wo = reflect(wf, m);
            wo.z = -wo.z;
            bs.sampled_flags = kGlossyTransmission;
            if (!(wo.z < 0.f) || !mac_mic(m, wf, wo, wf.z, false)) return BsdfSample{};
        } else if (u1 < p.spec_reflect + p.spec_trans + p.diffuse_reflect || !has(kDiffTrans)) {
            wo = warp::square_to_cosine_hemisphere(u2);
            bs.sampled_flags = kDiffuseReflection;
        } else {
            wo = -warp::square_to_cosine_hemisphere(u2);
            bs.sampled_flags = kDiffuseTransmission;
        }
        bs.wo = mulsign(wo, cos_i);
        Color value;
        eval_pdf(ctx.mode, v, wi, bs.wo, &value, &bs.pdf_w);
        if (!(bs.pdf_w > 0.f)) return BsdfSample{};
        bs.weight = value / bs.pdf_w;
        return sanitize(bs);
    }

    Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        Color value;
        float pdf;
        eval_pdf(ctx.mode, at(ctx.uv), wi, wo, &value, &pdf);
        return value;
    }
    float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const override {
        Color value;
        float pdf;
        eval_pdf(ctx.mode, at(ctx.uv), wi, wo, &value, &pdf);
        return pdf;
    }

private:
    struct Probabilities {
        float spec_reflect = 0.f, spec_trans = 0.f, diffuse_reflect = 0.f, diffuse_trans = 0.f;
    };
    // Mitsuba's lobe-selection probabilities (constant over directions).
    Probabilities probabilities(const Values& v) const {
        const float st = v[kSpecTrans], dt = 0.5f * v[kDiffTrans];
        Probabilities p;
        if (has(kSpecTrans)) {
            p.spec_reflect = 0.5f * st * spec_reflect_rate_;
            p.spec_trans = 0.5f * st * spec_trans_rate_;
        }
        p.diffuse_reflect = diffuse_reflect_rate_ * (1.f - st) * (1.f - dt);
        if (has(kDiffTrans)) p.diffuse_trans = diffuse_trans_rate_ * (1.f - st) * dt;
        const float total = p.spec_reflect + p.spec_trans + p.diffuse_reflect + p.diffuse_trans;
        if (!(total > 0.f)) return Probabilities{};
        const float inv = 1.f / total;
        p.spec_reflect *= inv;
        p.spec_trans *= inv;
        p.diffuse_reflect *= inv;
        p.diffuse_trans *= inv;
        return p;
    }

    // The transmission lobe's GGX, its roughness scaled by (0.65 eta - 0.35)
    // (Burley 2015, sec. 4.3, fig. 15).
    static MicrofacetDistribution trans_distribution(const Values& v) {
        return ggx(v[kAnisotropic], (0.65f * v[kEta] - 0.35f) * v[kRoughness]);
    }

    // The specular transmission f (without cos) from a, in front, to b,
    // behind: spec_trans base_color (1 - F) D' G' / (4 cos_a cos_b), wh the
    // half vector of a and b mirrored to a's side, with Mitsuba's checks of
    // the microfacet's sides (mac_mic_compatibility and G1's).
    static Color transmission(const Values& v, const MicrofacetDistribution& distr_t, const Vec3& a, const Vec3& b) {
        const Vec3 h = a + Vec3(b.x, b.y, -b.z);
        const float len = length(h);
        if (!(len > 0.f) || !(a.z > 0.f) || !(b.z < 0.f)) return Color(0.f);
        const Vec3 wh = h / len;
        if (!mac_mic(wh, a, b, a.z, false)) return Color(0.f);
        const float F = fresnel_dielectric(dot(a, wh), v[kEta]).F;
        return v.base * (v[kSpecTrans] * (1.f - F) * distr_t.D(wh) * distr_t.G(a, b, wh) / (4.f * a.z * -b.z));
    }

    void eval_pdf(TransportMode mode, const Values& v, const Vec3& wi_in, const Vec3& wo_in, Color* value,
                  float* pdf) const {
        *value = Color(0.f);
        *pdf = 0.f;
        const float cos_in = wi_in.z;
        if (cos_in == 0.f || !std::isfinite(cos_in)) return;
        // Both turned so that wi is in front: the sheet is the same from both sides.
        const Vec3 wi = mulsign(wi_in, cos_in), wo = mulsign(wo_in, cos_in);
        const float cos_i = wi.z, cos_o = wo.z;
        const bool reflect = cos_o > 0.f, refract = cos_o < 0.f;
        if (!reflect && !refract) return;
        const float st = v[kSpecTrans], dt = 0.5f * v[kDiffTrans], eta = v[kEta];
        // The half vector of wi and wo mirrored to wi's side.
        const Vec3 wo_r(wo.x, wo.y, std::fabs(wo.z));
        Vec3 wh = wi + wo_r;
        const float len = length(wh);
        if (!(len > 0.f) || !std::isfinite(len)) return;
        wh = wh / len;
        const bool refl_ok = reflect && mac_mic(wh, wi, wo, cos_i, true);
        const bool refr_ok = refract && mac_mic(wh, wi, wo, cos_i, false);
        const MicrofacetDistribution distr = ggx(v[kAnisotropic], v[kRoughness]);
        const MicrofacetDistribution distr_t = trans_distribution(v);

        Color f(0.f);
        if (has(kSpecTrans) && st > 0.f && (refl_ok || refract)) {
            if (refl_ok) {
                // F_thin = lerp(F, F_Schlick(tint R0(eta)), spec_tint) (Mitsuba's thin_fresnel).
                const float F = fresnel_dielectric(dot(wi, wh), eta).F;
                const float tint = v[kSpecTint];
                Color f_thin(F);
                if (has(kSpecTint))
                    f_thin =
                        Color(F * (1.f - tint)) + schlick(tint_of(v.base) * schlick_r0(eta), dot(wi, wh), eta) * tint;
                f += f_thin * (st * distr.D(wh) * distr.G(wi, wo, wh) / (4.f * cos_i));
            } else if (mode == TransportMode::Radiance) {
                f += transmission(v, distr_t, wi, wo) * std::fabs(cos_o);
            } else {
                // The adjoint, f(wo, wi) (Veach 1997, eq. 5.15): Mitsuba's
                // masks make this lobe slightly non-reciprocal (see the
                // file head), and light paths must see the transpose of
                // what camera paths see.
                f += transmission(v, distr_t, -wo, -wi) * std::fabs(cos_o);
            }
        }
        if (reflect && st < 1.f && dt < 1.f) {
            const float cos_d = dot(wh, wo);
            const float wd = (1.f - st) * (1.f - dt);
            f += v.base * (wd * cos_o * kInvPi * disney_diffuse(cos_i, cos_o, cos_d, v[kRoughness], v[kFlatness]));
            if (has(kSheen) && v[kSheen] > 0.f) f += sheen_term(v, cos_d) * (wd * cos_o);
        }
        if (refract && st < 1.f && has(kDiffTrans) && dt > 0.f)
            f += v.base * ((1.f - st) * dt * kInvPi * std::fabs(cos_o));
        *value = finite_or_zero(f);

        const Probabilities p = probabilities(v);
        float density = 0.f;
        if (has(kSpecTrans) && (refl_ok || refr_ok)) {
            const float dwh_dwo = std::fabs(1.f / (4.f * dot(wo_r, wh)));  // Walter eq. 14, with wo mirrored
            if (refl_ok) density += p.spec_reflect * distr.pdf_w(wi, wh) * dwh_dwo;
            if (refr_ok) density += p.spec_trans * distr_t.pdf_w(wi, wh) * dwh_dwo;
        }
        if (reflect) density += p.diffuse_reflect * warp::square_to_cosine_hemisphere_pdf_w(wo);
        if (refract) density += p.diffuse_trans * warp::square_to_cosine_hemisphere_pdf_w(-wo);
        *pdf = finite_or_zero(density);
    }

    float spec_reflect_rate_, spec_trans_rate_, diffuse_reflect_rate_, diffuse_trans_rate_;
};

}  // namespace

std::unique_ptr<Bsdf> make_principled(const BsdfDesc& d) {
    if (d.type == "principled") {
        check_textured_names(d, {"base_color", "roughness", "anisotropic", "metallic", "spec_trans", "spec_tint",
                                 "sheen", "sheen_tint", "flatness", "clearcoat", "clearcoat_gloss"});
        return std::make_unique<PrincipledBsdf>(d);
    }
    if (d.type == "principledthin") {
        check_textured_names(d, {"base_color", "roughness", "anisotropic", "spec_trans", "spec_tint", "sheen",
                                 "sheen_tint", "flatness", "eta", "diff_trans"});
        return std::make_unique<PrincipledThinBsdf>(d);
    }
    throw std::invalid_argument("bsdf '" + d.id + "': not a principled type: '" + d.type + "'");
}

}  // namespace rm
