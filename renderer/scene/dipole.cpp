#include "scene/dipole.h"

#include <cstdio>

#include <cmath>
#include <stdexcept>

#include "core/warp.h"
#include "scene/fresnel.h"

namespace rm {

namespace {

constexpr double kPiD = 3.14159265358979323846;

// One pole of the dipole at depth z (J01 eq. 4, one of its two terms without
// alpha' / (4 pi)): z (1 + sigma_tr d) exp(-sigma_tr d) / d^3, d = sqrt(r^2 + z^2)
// its distance to the surface point at r. `shift` is subtracted from the
// exponent (sigma_tr d - shift) to keep it in range; the caller undoes it.
double pole(double z, double sigma_tr, double r, double shift) {
    double d = std::sqrt(r * r + z * z);
    return z * (1.0 + sigma_tr * d) * std::exp(-(sigma_tr * d - shift)) / (d * d * d);
}

// The pole's share of 1 - CDF beyond r, integrated in closed form: with
// d = sqrt(r^2 + z^2), r dr = d dd and d/dd [-exp(-s d) / d] = (1 + s d) exp(-s d) / d^2,
// so integral_r^inf 2 pi r pole(r') dr' = 2 pi exp(-s d) / d * z; over the
// whole plane 2 pi exp(-s z). Their ratio: (z / d) exp(-s (d - z)).
double pole_tail(double z, double sigma_tr, double r) {
    double d = std::sqrt(r * r + z * z);
    return (z / d) * std::exp(-sigma_tr * (d - z));
}

// The exit lobe cos(wo) Sw(wo) = Ft(eta, wo) cos(wo) / (c pi) (PBR3 sec. 11.4.1;
// J01 eq. 6's outgoing Fresnel factor), cosine-sampled.
class DipoleExitLobe final : public Bsdf {
public:
    DipoleExitLobe(float eta, float c) : eta_(eta), c_(c) { flags_ = kDiffuseReflection; }
    BsdfSample sample(const BsdfContext&, const Vec3&, float, Vec2 u2) const override {
        BsdfSample s;
        s.wo = warp::square_to_cosine_hemisphere(u2);
        s.pdf_w = warp::square_to_cosine_hemisphere_pdf_w(s.wo);
        if (!(s.pdf_w > 0.f)) return BsdfSample{};
        s.weight = Color(ft(s.wo.z) / c_);  // (Ft cos / (c pi)) / (cos / pi)
        s.sampled_flags = kDiffuseReflection;
        return s;
    }
    Color eval(const BsdfContext&, const Vec3&, const Vec3& wo) const override {
        if (!(wo.z > 0.f)) return Color(0.f);
        return Color(ft(wo.z) * wo.z * kInvPi / c_);
    }
    float pdf_w(const BsdfContext&, const Vec3&, const Vec3& wo) const override {
        return warp::square_to_cosine_hemisphere_pdf_w(wo);
    }

private:
    float ft(float cos_o) const { return 1.f - fresnel_dielectric(cos_o, eta_).F; }
    float eta_, c_;
};

// 1 - Fdr_ext: the cosine-weighted hemispherical average of the Fresnel
// transmittance from outside, (1/pi) integral Ft cos dw = integral_0^1 Ft(mu) 2 mu dmu,
// integrated numerically (midpoint rule in mu^2, 4096 cells; error < 1e-6)
// rather than by a polynomial fit, so that Sw integrates to 1 to float
// precision: a white dipole must not reflect more than it receives.
float transmitted_fraction(float eta) {
    constexpr int n = 4096;
    double sum = 0.0;
    for (int i = 0; i < n; ++i) {
        double mu = std::sqrt((i + 0.5) / n);  // cells of equal mu^2: the weight 2 mu dmu is d(mu^2)
        sum += 1.0 - fresnel_dielectric(float(mu), eta).F;
    }
    return float(sum / n);
}

}  // namespace

Dipole::Dipole(const DipoleDesc& d) {
    auto bad = [&](const std::string& msg) {
        return std::invalid_argument("subsurface 'dipole' " + d.id + ": " + msg);
    };
    for (int c = 0; c < 3; ++c) {
        if (!(d.sigma_a[c] >= 0.f) || !std::isfinite(d.sigma_a[c])) throw bad("sigma_a must be finite and >= 0");
        if (!(d.sigma_s[c] >= 0.f) || !std::isfinite(d.sigma_s[c])) throw bad("sigma_s must be finite and >= 0");
    }
    if (!(d.g > -1.f && d.g < 1.f)) throw bad("g must lie in (-1, 1)");
    if (!(d.int_ior > 0.f && d.ext_ior > 0.f) || !std::isfinite(d.int_ior) || !std::isfinite(d.ext_ior))
        throw bad("int_ior and ext_ior must be finite and > 0");
    eta_ = d.int_ior / d.ext_ior;
    // J01 sec. 2.4 (after Groenhuis et al. 1983): the internal diffuse
    // Fresnel reflectance of a boundary of relative index eta, fitted as
    // Fdr = -1.440 / eta^2 + 0.710 / eta + 0.668 + 0.0636 eta, and
    // A = (1 + Fdr) / (1 - Fdr), the change in fluence by internal reflection.
    fdr_int = -1.440f / (eta_ * eta_) + 0.710f / eta_ + 0.668f + 0.0636f * eta_;
    fdr_int = clamp(fdr_int, 0.f, 0.99f);  // the fit leaves [0, 1) only far outside its range of eta
    A = (1.f + fdr_int) / (1.f - fdr_int);
    c_ = transmitted_fraction(eta_);
    if (!(c_ > 0.f)) throw bad("no light crosses a boundary of relative index " + std::to_string(eta_));
    for (int c = 0; c < 3; ++c) {
        // J01 sec. 2.4: reduced coefficients sigma_s' = sigma_s (1 - g),
        // sigma_t' = sigma_a + sigma_s', alpha' = sigma_s' / sigma_t', the
        // effective transport coefficient sigma_tr = sqrt(3 sigma_a sigma_t'),
        // D = 1 / (3 sigma_t'), the real source at z_r = 1 / sigma_t' below the
        // surface and the virtual one at z_v = z_r + 4 A D above it.
        double sa = d.sigma_a[c], ssp = double(d.sigma_s[c]) * (1.0 - d.g);
        double stp = sa + ssp;
        sigma_tp[c] = float(stp);
        if (!(stp > 0.0) || !std::isfinite(1.0 / stp)) {
            ok_[c] = false;  // neither scatters nor absorbs: no profile (and nothing comes back)
            alpha_p[c] = 0.f;
            continue;
        }
        ok_[c] = true;
        double a = ssp / stp, s = std::sqrt(3.0 * sa * stp);
        double zr = 1.0 / stp, zv = zr + 4.0 * A / (3.0 * stp);
        alpha_p[c] = float(a);
        sigma_tr[c] = float(s);
        z_r[c] = float(zr);
        z_v[c] = float(zv);
        // Total diffuse reflectance (J01, sec. 2.4, the integral of eq. 4):
        // R_d = (alpha' / 2) (exp(-sigma_tr z_r) + exp(-sigma_tr z_v))
        //     = (alpha' / 2) (1 + exp(-(4/3) A sqrt(3 (1 - alpha')))) exp(-sqrt(3 (1 - alpha'))).
        double er = std::exp(-s * zr), ev = std::exp(-s * zv);
        total_rd_[c] = float(0.5 * a * (er + ev));
        w_real_[c] = 1.0 / (1.0 + std::exp(-s * (zv - zr)));
        // r_max: where the normalised profile's CDF reaches kCdfMax
        // (tail() is decreasing: double, then bisect).
        double lo = 0.0, hi = zv;
        for (int i = 0; i < 2000 && tail(c, hi) > 1.0 - kCdfMax; ++i) hi *= 2.0;
        for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; ++i) {
            double mid = 0.5 * (lo + hi);
            (tail(c, mid) > 1.0 - kCdfMax ? lo : hi) = mid;
        }
        r_max_[c] = hi;
        if (!std::isfinite(hi) || !(hi > 0.0)) ok_[c] = false;
        // Probe rays span the profile's radius: beyond Embree's float range
        // (1.8e18) they cannot be traced, and long before it they lose all
        // precision. Refused here rather than when the first probe ray fails.
        if (ok_[c] && hi > 1e15) {
            char buf[200];
            std::snprintf(buf, sizeof buf,
                          "sigma_a and sigma_s (scale applied) give channel %d a scattering radius of %g, beyond "
                          "what float32 ray tracing represents (at most 1e15 here)",
                          c, hi);
            throw bad(buf);
        }
    }
    exit_ = std::make_unique<DipoleExitLobe>(eta_, c_);
}

double Dipole::rd(int c, double r) const {
    if (!ok_[c]) return 0.0;
    // J01 eq. 4: Rd(r) = alpha' / (4 pi) [z_r (1 + sigma_tr d_r) e^{-sigma_tr d_r} / d_r^3
    //                                  + z_v (1 + sigma_tr d_v) e^{-sigma_tr d_v} / d_v^3].
    double s = sigma_tr[c];
    return double(alpha_p[c]) / (4.0 * kPiD) * (pole(z_r[c], s, r, 0.0) + pole(z_v[c], s, r, 0.0));
}

Color Dipole::rd(float r) const { return {float(rd(0, r)), float(rd(1, r)), float(rd(2, r))}; }

double Dipole::tail(int c, double r) const {
    double w = w_real_[c];
    return w * pole_tail(z_r[c], sigma_tr[c], r) + (1.0 - w) * pole_tail(z_v[c], sigma_tr[c], r);
}

double Dipole::pdf_a(int c, double r) const {
    if (!ok_[c] || !(r >= 0.0) || r > r_max_[c]) return 0.0;
    // Rd / R_d, written with the exponents shifted by sigma_tr z_r so that
    // neither the profile nor its total underflows for large sigma_tr z.
    double s = sigma_tr[c], zr = z_r[c], zv = z_v[c];
    double num = pole(zr, s, r, s * zr) + pole(zv, s, r, s * zr);
    double den = 2.0 * kPiD * (1.0 + std::exp(-s * (zv - zr)));
    return num / den / kCdfMax;
}

double Dipole::sample_r(int c, double u) const {
    if (!ok_[c]) return -1.0;
    // Invert the normalised CDF 1 - tail(r) = u kCdfMax: tail() is the
    // exact mixture of the two poles' closed-form tails (see pole_tail),
    // so this is exact inversion, by Newton's method kept inside a
    // bisection bracket (the derivative of the tail is -2 pi r pdf).
    double target = 1.0 - std::min(std::max(u, 0.0), 1.0) * kCdfMax;
    double lo = 0.0, hi = r_max_[c], r = 0.5 * hi;
    for (int i = 0; i < 100; ++i) {
        double f = tail(c, r) - target;
        if (f > 0.0)
            lo = r;
        else
            hi = r;
        if (std::fabs(f) < 1e-12 || hi - lo <= 1e-12 * hi) break;
        double dfdr = -2.0 * kPiD * r * pdf_a(c, r) * kCdfMax;
        double next = dfdr < 0.0 ? r - f / dfdr : 0.5 * (lo + hi);
        r = (next > lo && next < hi && std::isfinite(next)) ? next : 0.5 * (lo + hi);
    }
    return r;
}

}  // namespace rm
