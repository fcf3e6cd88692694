// The dipole BSSRDF of Jensen, Marschner, Levoy and Hanrahan 2001, "A
// Practical Model for Subsurface Light Transport" (SIGGRAPH 2001; "J01"
// below): a fast, biased stand-in for random-walk subsurface scattering
// (a dense medium behind a dielectric boundary, volpath.cpp). Mitsuba 0.6's
// `dipole` subsurface plugin, nested in a shape; the loader documents the
// parameters.
//
// The BSSRDF, in the separable, normalised form of pbrt-v3 (PBR3 sec. 11.4.1,
// SeparableBSSRDF and its Sw), with J01's dipole profile as its spatial term:
//   S(xo, wo; xi, wi) = Ft(eta, wo) Rd(|xi - xo|) Sw(wi),
//   Sw(wi) = Ft(eta, wi) / (c pi),  c = 1 - Fdr_ext(eta),
// which is J01 eq. 6's (1/pi) Ft Rd Ft with the incident Fresnel term
// normalised so that the integral of Sw(w) cos(w) over the hemisphere is 1:
// all the light the profile says leaves (its total diffuse reflectance
// R_d = integral of Rd over the plane) leaves. J01's own form loses another
// factor (1 - Fdr_ext) ~ 0.91 at eta 1.5 that its R_d already accounts for
// (the boundary condition A below is that internal reflection). pbrt-v3
// takes c = 1 - 2 FM1(1/eta) from a fit of the Fresnel moment; here c is
// integrated numerically (dipole.cpp). Under
// uniform illumination L of a half space the reflected radiance is then
// L (Fr(wo) + Ft(wo) R_d): exactly L for a white (non-absorbing) medium.
// No eta^2 radiance factor: light enters and leaves the same medium.
#pragma once
#include <memory>
#include <string>

#include "core/math.h"
#include "core/spectrum.h"
#include "scene/bsdf.h"

namespace rm {

struct DipoleDesc {
    std::string id;      // for error messages
    Color sigma_a{0.f};  // absorption per unit length (scale applied)
    Color sigma_s{1.f};  // scattering per unit length, NOT reduced (scale applied)
    float g = 0.f;       // mean cosine of the phase function: sigma_s' = sigma_s (1 - g)
    float int_ior = 1.5046f, ext_ior = 1.000277f;
};

class Dipole {
public:
    // Throws std::invalid_argument naming desc.id on a bad value.
    explicit Dipole(const DipoleDesc& desc);

    // The radial profile sampler covers this fraction of each channel's
    // R_d; exit points farther than r_max(ch) are never proposed by that
    // channel (pbrt-v3 truncates at the same 0.999, PBR3 sec. 15.4).
    static constexpr double kCdfMax = 0.999;

    // J01 eq. 4: diffuse reflectance per unit area at distance r, RGB.
    Color rd(float r) const;
    double rd(int ch, double r) const;
    // Total diffuse reflectance, the integral of rd over the plane (J01
    // sec. 2.4's closed form; see dipole.cpp).
    Color total_rd() const { return total_rd_; }
    // Distance r drawn with the density 2 pi r Rd_ch(r) / (kCdfMax R_d,ch)
    // on [0, r_max(ch)] by inverting its CDF (exact, see dipole.cpp) from
    // u in [0, 1); -1 where the channel has no profile (sigma_t' = 0).
    double sample_r(int ch, double u) const;
    // Density per unit area of the point at distance r on the plane, as
    // sample_r (with a uniform angle) proposes it.
    double pdf_a(int ch, double r) const;
    double r_max(int ch) const { return r_max_[ch]; }
    bool channel_ok(int ch) const { return ok_[ch]; }

    float eta() const { return eta_; }  // int_ior / ext_ior
    // 1 - Fdr_ext: normalisation of Sw.
    float sw_norm() const { return c_; }
    // The exit lobe cos(w) Sw(w) as a BSDF on the outside of the exit point
    // (local frame, z = outward normal): what next event estimation and the
    // continuation sample at xi.
    const Bsdf& exit_lobe() const { return *exit_; }

    Color sigma_tr, z_r, z_v, alpha_p, sigma_tp;  // per channel (J01 sec. 2.4)
    float A = 1.f, fdr_int = 0.f;

private:
    double tail(int ch, double r) const;  // 1 - CDF(r), the unnormalised mixture over the two poles
    float eta_ = 1.f, c_ = 1.f;
    Color total_rd_{0.f};
    double r_max_[3] = {0, 0, 0};
    double w_real_[3] = {0, 0, 0};  // share of the real source in the normalised profile
    bool ok_[3] = {false, false, false};
    std::unique_ptr<Bsdf> exit_;
};

}  // namespace rm
