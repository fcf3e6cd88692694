#include "scene/microfacet.h"

#include <cmath>
#include <vector>

#include "core/sh.h"
#include "core/warp.h"
#include "scene/fresnel.h"

namespace rm {

namespace {

constexpr double kPiD = 3.14159265358979323846;
constexpr double kInvSqrtPiD = 0.56418958354775628695;

// Inverse error function in double. Initial guess from Giles 2010,
// "Approximating the erfinv function" (GPU Computing Gems Jade, single-precision
// branch-light polynomial), refined by two Newton steps on erf(x) - y, whose
// derivative is 2/sqrt(pi) exp(-x^2).
double erfinv(double y) {
    if (y <= -1.0) return -kInf;
    if (y >= 1.0) return kInf;
    double w = -std::log((1.0 - y) * (1.0 + y)), p;
    if (w < 5.0) {
        w -= 2.5;
        p = 2.81022636e-08;
        p = 3.43273939e-07 + p * w;
        p = -3.5233877e-06 + p * w;
        p = -4.39150654e-06 + p * w;
        p = 0.00021858087 + p * w;
        p = -0.00125372503 + p * w;
        p = -0.00417768164 + p * w;
        p = 0.246640727 + p * w;
        p = 1.50140941 + p * w;
    } else {
        w = std::sqrt(w) - 3.0;
        p = -0.000200214257;
        p = 0.000100950558 + p * w;
        p = 0.00134934322 + p * w;
        p = -0.00367342844 + p * w;
        p = 0.00573950773 + p * w;
        p = -0.0076224613 + p * w;
        p = 0.00943887047 + p * w;
        p = 1.00167406 + p * w;
        p = 2.83297682 + p * w;
    }
    double x = p * y;
    for (int i = 0; i < 2; ++i) {
        double d = 2.0 * kInvSqrtPiD * std::exp(-x * x);
        if (!(d > 0.0)) break;
        x -= (std::erf(x) - y) / d;
    }
    return x;
}

// Slopes of a visible normal of the unit-roughness Beckmann distribution seen
// from elevation cos_theta_i (> 0). Jakob 2014, "An Improved Visible Normal
// Sampling Routine for the Beckmann Distribution" (tech. report): the x slope is
// found by Newton iterations on the (monotone) CDF parameterised in the erf
// domain, x in [-1, erf(cot theta_i)], starting from the closed-form solution
// of the grazing case; the y slope is an independent Gaussian (Heitz & d'Eon
// 2014, sec. 4 and appendix). Double precision and a bracket keep it finite
// at grazing angles where the CDF's derivative vanishes at the upper end.
Vec2 beckmann_visible_slopes_11(double cos_theta_i, Vec2 u) {
    const double ux = std::min(std::max(double(u.x), 1e-6), 1.0 - 1e-6);
    const double uy = std::min(std::max(double(u.y), 1e-6), 1.0 - 1e-6);
    const double sin_theta_i = std::sqrt(std::max(0.0, 1.0 - cos_theta_i * cos_theta_i));
    const double tan_theta_i = sin_theta_i / cos_theta_i;
    const double cot_theta_i = cos_theta_i / sin_theta_i;  // +inf at normal incidence

    const double maxval = std::erf(cot_theta_i);
    const double lo = -1.0 + 1e-12, hi = std::min(maxval, 1.0 - 1e-12);
    double x = maxval - (maxval + 1.0) * std::erf(std::sqrt(-std::log(ux)));
    x = std::min(std::max(x, lo), hi);

    // Normalisation of the CDF: 1 + erf(cot) + tan exp(-cot^2) / sqrt(pi),
    // which is 2 (1 + Lambda(wi)) for unit roughness.
    const double tail = tan_theta_i > 0.0 ? kInvSqrtPiD * tan_theta_i * std::exp(-cot_theta_i * cot_theta_i) : 0.0;
    const double target = ux * (1.0 + maxval + tail);

    for (int i = 0; i < 8; ++i) {
        double slope = erfinv(x);
        double value = 1.0 + x + kInvSqrtPiD * tan_theta_i * std::exp(-slope * slope) - target;
        double derivative = 1.0 - slope * tan_theta_i;
        if (!(derivative > 0.0) || !std::isfinite(value)) break;
        double step = value / derivative;
        x = std::min(std::max(x - step, lo), hi);
        if (std::fabs(step) < 1e-13) break;
    }
    return {float(erfinv(x)), float(erfinv(2.0 * uy - 1.0))};
}

}  // namespace

MicrofacetDistribution::MicrofacetDistribution(MicrofacetType type, float alpha_u, float alpha_v, bool sample_visible)
    : type_(type),
      alpha_u_(std::max(alpha_u, kMinAlpha)),
      alpha_v_(std::max(alpha_v, kMinAlpha)),
      sample_visible_(sample_visible) {}

void MicrofacetDistribution::scale_alpha(float s) {
    alpha_u_ = std::max(alpha_u_ * s, kMinAlpha);
    alpha_v_ = std::max(alpha_v_ * s, kMinAlpha);
}

float MicrofacetDistribution::D(const Vec3& m) const {
    if (!(m.z > 0.f)) return 0.f;
    const double au = alpha_u_, av = alpha_v_;
    const double x = m.x / au, y = m.y / av, z = m.z;
    const double z2 = z * z;
    double result;
    if (type_ == MicrofacetType::Beckmann) {
        // Walter et al. 2007, eq. 25, with the anisotropic exponent
        // -(x^2/au^2 + y^2/av^2) / cos^2 (Heitz 2014, sec. 5.4).
        result = std::exp(-(x * x + y * y) / z2) / (kPiD * au * av * z2 * z2);
    } else {
        // Walter et al. 2007, eq. 33, anisotropic form (Heitz 2014, sec. 5.4):
        // 1 / (pi au av (x^2/au^2 + y^2/av^2 + z^2)^2).
        const double s = x * x + y * y + z2;
        result = 1.0 / (kPiD * au * av * s * s);
    }
    // Like Mitsuba: drop vanishing values so later divisions stay finite.
    if (!(result * z > 1e-20) || !std::isfinite(result)) return 0.f;
    return float(result);
}

float MicrofacetDistribution::lambda(const Vec3& v) const {
    const double xy = double(alpha_u_ * v.x) * (alpha_u_ * v.x) + double(alpha_v_ * v.y) * (alpha_v_ * v.y);
    if (xy == 0.0) return 0.f;  // normal incidence: nothing is masked
    const double z2 = double(v.z) * v.z;
    if (z2 == 0.0) return kInf;         // grazing: everything is masked
    const double tan2_alpha = xy / z2;  // (alpha_o tan theta_o)^2 with the projected roughness
    if (type_ == MicrofacetType::GGX) {
        // Lambda = (-1 + sqrt(1 + alpha^2 tan^2)) / 2.
        return float(0.5 * (std::sqrt(1.0 + tan2_alpha) - 1.0));
    }
    // Beckmann, a = 1 / (alpha tan theta):
    // Lambda = (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi)), written with
    // erfc so that the difference of the two terms keeps its precision.
    const double a = 1.0 / std::sqrt(tan2_alpha);
    const double l = 0.5 * (std::exp(-a * a) * kInvSqrtPiD / a - std::erfc(a));
    return float(std::max(l, 0.0));
}

float MicrofacetDistribution::G1(const Vec3& v, const Vec3& m) const {
    // Consistent orientation: v cannot see the back of the microfacet.
    if (!(dot(v, m) * v.z > 0.f)) return 0.f;
    const float l = lambda(v);
    if (!std::isfinite(l)) return 0.f;
    return 1.f / (1.f + l);
}

MicrofacetSample MicrofacetDistribution::sample(const Vec3& wi, Vec2 u) const {
    return sample_visible_ ? sample_visible_normal(wi, u) : sample_all(u);
}

float MicrofacetDistribution::pdf_w(const Vec3& wi, const Vec3& m) const {
    return sample_visible_ ? pdf_visible(wi, m) : pdf_all(m);
}

MicrofacetSample MicrofacetDistribution::sample_all(Vec2 u) const {
    // Azimuth: uniform for isotropic roughness; otherwise the marginal of
    // D cos over theta, p(phi) ~ 1 / (cos^2/au^2 + sin^2/av^2), by inversion
    // (the same for Beckmann and GGX; PBR3 sec. 8.4.3 / Mitsuba).
    float phi;
    if (alpha_u_ == alpha_v_) {
        phi = 2.f * kPi * u.y;
    } else {
        phi = std::atan(alpha_v_ / alpha_u_ * std::tan(2.f * kPi * u.y + 0.5f * kPi));
        if (u.y > 0.5f) phi += kPi;
    }
    const float cos_phi = std::cos(phi), sin_phi = std::sin(phi);
    const float alpha2 = 1.f / (sqr(cos_phi / alpha_u_) + sqr(sin_phi / alpha_v_));

    // Elevation by inversion of the radial CDF: Walter et al. 2007, eq. 28
    // (Beckmann: tan^2 = -alpha^2 log(1 - u)) and eq. 35 (GGX: tan^2 = alpha^2 u / (1 - u)).
    const float ux = std::min(u.x, 1.f - 1e-7f);
    float tan2;
    if (type_ == MicrofacetType::Beckmann)
        tan2 = -alpha2 * std::log1p(-ux);
    else
        tan2 = alpha2 * ux / (1.f - ux);
    // sin from tan, not sqrt(1 - cos^2): for alpha ~ 1e-4, cos rounds to 1 and
    // the latter would collapse every normal onto the macro normal.
    const float cos_theta = 1.f / std::sqrt(1.f + tan2);
    const float sin_theta = std::isfinite(tan2) ? std::sqrt(tan2) * cos_theta : 1.f;

    MicrofacetSample s;
    s.m = Vec3(cos_phi * sin_theta, sin_phi * sin_theta, cos_theta);
    s.pdf_w = pdf_all(s.m);
    return s;
}

MicrofacetSample MicrofacetDistribution::sample_visible_normal(const Vec3& wi, Vec2 u) const {
    MicrofacetSample s;
    if (!(wi.z > 0.f)) return s;

    // Stretch wi to the configuration of unit roughness (Heitz & d'Eon 2014,
    // sec. 4, step 1; Heitz 2018, listing 1).
    const Vec3 wh = normalize(Vec3(alpha_u_ * wi.x, alpha_v_ * wi.y, wi.z));
    if (type_ == MicrofacetType::GGX) {
        // Heitz 2018, "Sampling the GGX Distribution of Visible Normals", JCGT
        // 7(4), listing 1: the visible part of the unit hemisphere projected on
        // the plane orthogonal to wh is a half disk plus a half ellipse; sample
        // it uniformly, lift to the hemisphere, unstretch.
        const float lensq = wh.x * wh.x + wh.y * wh.y;
        const Vec3 t1 = lensq > 0.f ? Vec3(-wh.y, wh.x, 0.f) / std::sqrt(lensq) : Vec3(1.f, 0.f, 0.f);
        const Vec3 t2 = cross(wh, t1);
        const float r = std::sqrt(u.x), phi = 2.f * kPi * u.y;
        const float p1 = r * std::cos(phi);
        float p2 = r * std::sin(phi);
        const float sh = 0.5f * (1.f + wh.z);
        p2 = (1.f - sh) * safe_sqrt(1.f - p1 * p1) + sh * p2;
        const Vec3 nh = t1 * p1 + t2 * p2 + wh * safe_sqrt(1.f - p1 * p1 - p2 * p2);
        const Vec3 ne(alpha_u_ * nh.x, alpha_v_ * nh.y, std::max(0.f, nh.z));
        const float len = length(ne);
        if (!(len > 0.f)) return s;
        s.m = ne / len;
    } else {
        // Beckmann: sample the slopes of the unit-roughness VNDF (Jakob 2014),
        // rotate them to wi's azimuth and unstretch (Heitz & d'Eon 2014, sec. 4,
        // steps 2-4).
        const float sin_theta = std::sqrt(wh.x * wh.x + wh.y * wh.y);
        const float cos_phi = sin_theta > 0.f ? wh.x / sin_theta : 1.f;
        const float sin_phi = sin_theta > 0.f ? wh.y / sin_theta : 0.f;
        const Vec2 sl = beckmann_visible_slopes_11(wh.z, u);
        const float sx = (cos_phi * sl.x - sin_phi * sl.y) * alpha_u_;
        const float sy = (sin_phi * sl.x + cos_phi * sl.y) * alpha_v_;
        const Vec3 m(-sx, -sy, 1.f);
        const float len = length(m);
        if (!std::isfinite(len)) return s;
        s.m = m / len;
    }
    s.pdf_w = pdf_visible(wi, s.m);
    return s;
}

float MicrofacetDistribution::pdf_visible(const Vec3& wi, const Vec3& m) const {
    // Heitz & d'Eon 2014, eq. 2: D_wi(m) = G1(wi, m) max(0, wi.m) D(m) / cos theta_i.
    if (!(wi.z > 0.f)) return 0.f;
    const float wm = dot(wi, m);
    if (!(wm > 0.f)) return 0.f;
    const float p = G1(wi, m) * wm * D(m) / wi.z;
    return std::isfinite(p) ? p : 0.f;
}

namespace {

// E_m[g(m)] over the visible normals of wi by the res x res Gauss-Legendre
// rule on [0, 1]^2 mapped through sample_visible_normal(), in double.
template <typename G>
double visible_normal_expectation(const MicrofacetDistribution& distr, const Vec3& wi, int res, G g) {
    std::vector<double> x, w;
    gauss_legendre(res, x, w);
    const bool ggx = distr.type() == MicrofacetType::GGX;
    // With wi in the xz plane and isotropic roughness the integrand is even in
    // m.y, and the node mirrored about 0 along one axis (GGX: the first, which
    // becomes the disk's x and then m.y; Beckmann: the second, the y slope)
    // yields the mirrored normal: half the nodes, counted twice, give the
    // same sum (to rounding) at half the cost. The nodes come in decreasing
    // order, x[res - 1 - k] = -x[k].
    const bool mirror = wi.y == 0.f && distr.alpha_u() == distr.alpha_v() && res % 2 == 0;
    double sum = 0.0;
    for (int i = 0; i < res; ++i) {
        for (int j = 0; j < res; ++j) {
            if (mirror && (ggx ? i : j) >= res / 2) continue;
            Vec2 u(float(0.5 * x[size_t(i)] + 0.5), float(0.5 * x[size_t(j)] + 0.5));
            if (ggx) {
                // Mitsuba's GGX sampler starts from the concentric disk map
                // (Shirley & Chiu 1997), ours from the polar one (r = sqrt(u.x),
                // phi = 2 pi u.y): the nodes go through the former and back
                // through the latter, so that the rule sees the same normals.
                const Vec2 d = warp::square_to_uniform_disk_concentric(u);
                float phi = std::atan2(d.y, d.x) * (0.5f * kInvPi);
                if (phi < 0.f) phi += 1.f;
                u = Vec2(std::min(d.x * d.x + d.y * d.y, 1.f), std::min(phi, 1.f - 1e-7f));
            }
            const MicrofacetSample ms = distr.sample_visible_normal(wi, u);
            if (!(ms.pdf_w > 0.f)) continue;
            // The weights sum to 2 per axis on [-1, 1]: 1/4 maps them to [0, 1]^2.
            sum += (mirror ? 0.5 : 0.25) * w[size_t(i)] * w[size_t(j)] * g(ms.m);
        }
    }
    return sum;
}

}  // namespace

double microfacet_reflectance(const MicrofacetDistribution& distr, const Vec3& wi, float eta, int res) {
    if (!(wi.z > 0.f)) return 0.0;
    return visible_normal_expectation(distr, wi, res, [&](const Vec3& m) {
        const Vec3 wo = reflect(wi, m);
        if (!(wo.z > 0.f)) return 0.0;
        return double(fresnel_dielectric(dot(wi, m), eta).F) * distr.G1(wo, m);
    });
}

double microfacet_transmittance(const MicrofacetDistribution& distr, const Vec3& wi, float eta, int res) {
    if (!(wi.z > 0.f)) return 0.0;
    return visible_normal_expectation(distr, wi, res, [&](const Vec3& m) {
        const FresnelDielectric fr = fresnel_dielectric(dot(wi, m), eta);
        const Vec3 wo = refract(wi, m, fr.cos_theta_t, fr.eta_ti);
        if (!(wo.z < 0.f)) return 0.0;
        return double(1.f - fr.F) * distr.G1(wo, m);
    });
}

}  // namespace rm
