// Fresnel equations and the specular reflect/refract helpers shared by the
// BSDFs. Conventions follow Mitsuba 3 (include/mitsuba/render/fresnel.h) so that
// our BSDFs agree with the reference renderer sample for sample: directions are
// local (z = normal), both pointing away from the surface, and a relative IOR
// eta = eta_interior / eta_exterior, "interior" being the side opposite the
// normal.
#pragma once
#include <complex>

#include "core/math.h"
#include "core/spectrum.h"

namespace rm {

struct FresnelDielectric {
    float F = 1.f;            // unpolarised reflectance
    float cos_theta_t = 0.f;  // signed cosine of the transmitted direction (opposite side to wi)
    float eta_it = 1.f;       // eta_t / eta_i along the direction of travel
    float eta_ti = 1.f;       // 1 / eta_it; also the scale of the refracted tangential part
};

// Unpolarised Fresnel reflectance of a smooth dielectric interface, the mean of
// the s and p amplitude reflectances squared (Born & Wolf, "Principles of
// Optics", 7th ed., sec. 1.5.2, eqs. 21a and 21b; PBR4 eqs. 9.5 and 9.6).
// cos_theta_i >= 0 means wi is on the normal (exterior) side. Total internal
// reflection gives F = 1 and cos_theta_t = 0; eta == 1 gives F = 0 everywhere
// (index matched, even at grazing incidence), as Mitsuba's fresnel() does.
inline FresnelDielectric fresnel_dielectric(float cos_theta_i, float eta) {
    FresnelDielectric r;
    const bool outside = cos_theta_i >= 0.f;
    r.eta_it = outside ? eta : 1.f / eta;
    r.eta_ti = outside ? 1.f / eta : eta;

    // Snell's law: sin^2 theta_t = eta_ti^2 sin^2 theta_i.
    const float cos_i = std::fabs(cos_theta_i);
    const float cos_t_sqr = 1.f - r.eta_ti * r.eta_ti * std::max(0.f, 1.f - cos_i * cos_i);
    const float cos_t = safe_sqrt(cos_t_sqr);

    if (eta == 1.f) {
        r.F = 0.f;
    } else if (cos_i == 0.f || cos_t_sqr <= 0.f) {
        r.F = 1.f;  // grazing incidence or total internal reflection
    } else {
        const float a_s = (cos_i - r.eta_it * cos_t) / (cos_i + r.eta_it * cos_t);
        const float a_p = (cos_t - r.eta_it * cos_i) / (cos_t + r.eta_it * cos_i);
        r.F = clamp(0.5f * (a_s * a_s + a_p * a_p), 0.f, 1.f);
    }
    // The transmitted ray leaves on the other side of the interface.
    r.cos_theta_t = std::signbit(cos_theta_i) ? cos_t : -cos_t;
    return r;
}

// Unpolarised Fresnel reflectance of a conductor with complex relative IOR
// eta + i k, exact (no Schlick-style approximation): the Fresnel amplitudes
// r_s = (cos_i - n cos_t) / (cos_i + n cos_t), r_p = (n cos_i - cos_t) / (n cos_i + cos_t)
// with complex n and n cos_t = sqrt(n^2 - sin^2 theta_i) (Born & Wolf sec. 14.2;
// PBR4 sec. 9.3.6, eq. 9.6 with complex eta). Evaluated in double to keep the
// ratio well conditioned for large k. Light arrives from outside (cos_theta_i
// is clamped to [0, 1]). eta = 0, k = 1 (Mitsuba's material "none") gives
// exactly F = 1: both amplitudes are a number over its conjugate.
inline float fresnel_conductor(float cos_theta_i, float eta, float k) {
    using C = std::complex<double>;
    const double ci = clamp(cos_theta_i, 0.f, 1.f);
    const double s2 = 1.0 - ci * ci;
    const C n(eta, k);
    const C n2 = n * n;
    const C n_cos_t = std::sqrt(n2 - s2);  // = n cos theta_t (principal root, Im >= 0)
    const double ds = std::norm(ci + n_cos_t);
    const double dp = std::norm(n2 * ci + n_cos_t);
    // Degenerate (index matched n = 1 at exactly grazing incidence): the limit is 1.
    const double rs = ds > 0.0 ? std::norm(ci - n_cos_t) / ds : 1.0;
    const double rp = dp > 0.0 ? std::norm(n2 * ci - n_cos_t) / dp : 1.0;
    const double F = 0.5 * (rs + rp);
    return std::isfinite(F) ? float(std::min(std::max(F, 0.0), 1.0)) : 1.f;
}

inline Color fresnel_conductor(float cos_theta_i, const Color& eta, const Color& k) {
    return {fresnel_conductor(cos_theta_i, eta.x, k.x), fresnel_conductor(cos_theta_i, eta.y, k.y),
            fresnel_conductor(cos_theta_i, eta.z, k.z)};
}

// Hemispherical average of the dielectric Fresnel reflectance under diffuse
// (cosine-weighted) illumination, "Fdr". The same fits Mitsuba 3 uses, so that
// the plastic BSDF normalises its internal scattering identically:
// eta < 1: Egan & Hilgeman 1973, "Optical Properties of Inhomogeneous Materials";
// eta >= 1: d'Eon & Irving 2011, "A Quantized-Diffusion Model for Rendering
// Translucent Materials", eq. 5 (polynomial in 1/eta).
inline float fresnel_diffuse_reflectance(float eta) {
    if (eta < 1.f) return -1.4399f * (eta * eta) + 0.7099f * eta + 0.6681f + 0.0636f / eta;
    const float i1 = 1.f / eta, i2 = i1 * i1, i3 = i2 * i1, i4 = i3 * i1, i5 = i4 * i1;
    return 0.919317f - 3.4793f * i1 + 6.75335f * i2 - 7.80989f * i3 + 4.98554f * i4 - 1.36881f * i5;
}

// Mirror reflection about the local normal (0, 0, 1).
inline Vec3 reflect_local(const Vec3& wi) { return {-wi.x, -wi.y, wi.z}; }

// Refraction about the local normal, given fresnel_dielectric()'s cos_theta_t
// and eta_ti (PBR4 eq. 9.4 in local coordinates).
inline Vec3 refract_local(const Vec3& wi, float cos_theta_t, float eta_ti) {
    return {-eta_ti * wi.x, -eta_ti * wi.y, cos_theta_t};
}

// Refraction about a microfacet normal m, given fresnel_dielectric(dot(wi, m))'s
// cos_theta_t and eta_ti (Walter et al. 2007, eq. 40):
// wo = (eta_ti (wi.m) + cos_theta_t) m - eta_ti wi, with cos_theta_t signed.
inline Vec3 refract(const Vec3& wi, const Vec3& m, float cos_theta_t, float eta_ti) {
    return m * (dot(wi, m) * eta_ti + cos_theta_t) - wi * eta_ti;
}

}  // namespace rm
