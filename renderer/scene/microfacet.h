// Anisotropic microfacet normal distributions (Beckmann and GGX /
// Trowbridge-Reitz) with Smith's separable masking-shadowing and two sampling
// routines: the full distribution D(m) cos(theta_m), and the distribution of
// visible normals (VNDF) D_wi(m) = G1(wi, m) max(0, wi.m) D(m) / cos(theta_i)
// (Heitz & d'Eon 2014, "Importance Sampling Microfacet-Based BSDFs using the
// Distribution of Visible Normals", eq. 2).
//
// Directions are in the local shading frame (z = macro normal); alpha_u is the
// roughness along x (the tangent), alpha_v along y. Semantics follow Mitsuba 3's
// MicrofacetDistribution (include/mitsuba/render/microfacet.h) except where a
// comment says otherwise:
// - alpha is clamped to >= 1e-4, as Mitsuba does for numerical stability;
// - Beckmann's Smith G1 uses the exact Lambda (erfc form) where Mitsuba uses
//   Walter's rational fit (< 0.35% relative error). With the exact Lambda the
//   VNDF pdf integrates to 1 and is exactly the density of sample_visible(),
//   which our chi-square tests and MIS weights rely on.
#pragma once
#include "core/math.h"

namespace rm {

enum class MicrofacetType { Beckmann, GGX };

struct MicrofacetSample {
    Vec3 m{0, 0, 1};    // sampled microfacet normal (upper hemisphere)
    float pdf_w = 0.f;  // solid-angle density of m; 0 = failed
};

class MicrofacetDistribution {
public:
    static constexpr float kMinAlpha = 1e-4f;

    MicrofacetDistribution(MicrofacetType type, float alpha_u, float alpha_v, bool sample_visible);

    MicrofacetType type() const { return type_; }
    float alpha_u() const { return alpha_u_; }
    float alpha_v() const { return alpha_v_; }
    bool sample_visible() const { return sample_visible_; }
    // Walter et al. 2007 widen the lobe they sample from (end of sec. 5.3);
    // only used with sample_visible == false.
    void scale_alpha(float s);

    // Normal distribution D(m) per steradian of m; 0 for m.z <= 0.
    float D(const Vec3& m) const;
    // Smith's Lambda(v), with G1 = 1 / (1 + Lambda) (Heitz 2014, "Understanding
    // the Masking-Shadowing Function in Microfacet-Based BRDFs", JCGT 3(2),
    // sec. 5.3 for the isotropic closed forms, sec. 5.4 for anisotropy through
    // the projected roughness).
    float lambda(const Vec3& v) const;
    // Smith masking G1(v, m) = chi+(v.m / v.n) / (1 + Lambda(v)) (Heitz 2014,
    // sec. 5.1): 0 when v sees the back of m.
    float G1(const Vec3& v, const Vec3& m) const;
    // Separable masking-shadowing G = G1(wi, m) G1(wo, m) (as Mitsuba).
    float G(const Vec3& wi, const Vec3& wo, const Vec3& m) const { return G1(wi, m) * G1(wo, m); }

    // Samples m with the configured technique; wi must be in the upper hemisphere.
    MicrofacetSample sample(const Vec3& wi, Vec2 u) const;
    // Density of sample(wi, .) at m (solid angle of m).
    float pdf_w(const Vec3& wi, const Vec3& m) const;

    // The two techniques, usable directly.
    MicrofacetSample sample_all(Vec2 u) const;                             // pdf = D(m) cos theta_m
    MicrofacetSample sample_visible_normal(const Vec3& wi, Vec2 u) const;  // pdf = VNDF
    float pdf_all(const Vec3& m) const { return D(m) * std::max(m.z, 0.f); }
    float pdf_visible(const Vec3& wi, const Vec3& m) const;

private:
    MicrofacetType type_;
    float alpha_u_, alpha_v_;
    bool sample_visible_;
};

// Single-scattering directional albedos of a rough dielectric interface of
// relative IOR eta (eta_t / eta_i as seen from wi, wi.z > 0) with this
// distribution of smooth facets: the expectation over visible normals m
// (Heitz & d'Eon 2014, eq. 2) of the Fresnel-weighted (Walter et al. 2007,
// eqs. 20-21 integrated over wo) light that leaves the facet unmasked,
//   reflectance(wi)   = E_m[F(wi.m) G1(wo_r, m)],       wo_r = reflect(wi, m), wo_r.z > 0,
//   transmittance(wi) = E_m[(1 - F(wi.m)) G1(wo_t, m)], wo_t = refract(wi, m), wo_t.z < 0.
// As Mitsuba 3's eval_reflectance / eval_transmittance
// (include/mitsuba/render/microfacet.h), which roughplastic tabulates: a
// res x res Gauss-Legendre product rule over the unit square of
// sample_visible_normal()'s random numbers, so that the visible-normal
// density is absorbed by the warp (for GGX the nodes are first taken through
// Mitsuba's concentric disk map, so that both rules use the same normals).
// The distribution's sample_visible flag is
// not consulted (the visible normals are always used).
double microfacet_reflectance(const MicrofacetDistribution& distr, const Vec3& wi, float eta, int res);
double microfacet_transmittance(const MicrofacetDistribution& distr, const Vec3& wi, float eta, int res);

}  // namespace rm
