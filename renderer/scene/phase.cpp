#include "scene/phase.h"

#include <stdexcept>

#include "core/warp.h"

namespace rm {

namespace {

class IsotropicPhase final : public PhaseFunction {
public:
    PhaseSample sample(const Vec3&, Vec2 u) const override {
        PhaseSample ps;
        ps.wo = warp::square_to_uniform_sphere(u);
        ps.pdf_w = kInv4Pi;
        ps.weight = 1.f;
        return ps;
    }
    float eval(const Vec3&, const Vec3&) const override { return kInv4Pi; }
};

// Henyey & Greenstein 1941, "Diffuse radiation in the galaxy", ApJ 93:70:
// p(mu) = (1 - g^2) / (4 pi (1 + g^2 + 2 g mu)^(3/2)) with mu = wi . wo
// (wi pointing back along the incoming ray, hence the + sign).
class HenyeyGreensteinPhase final : public PhaseFunction {
public:
    explicit HenyeyGreensteinPhase(float g) : g_(g) {}
    float eval(const Vec3& wi, const Vec3& wo) const override { return hg(dot(wi, wo)); }
    PhaseSample sample(const Vec3& wi, Vec2 u) const override {
        // Inverse CDF in mu' = -mu (the cosine to the propagation direction -wi),
        // whose density is proportional to (1 + g^2 - 2 g mu')^(-3/2)
        // (PBR4 sec. 11.3.1, eq. 11.13 inverted).
        float mu_p;
        if (std::fabs(g_) < 1e-3f) {
            mu_p = 1.f - 2.f * u.x;
        } else {
            float s = (1.f - g_ * g_) / (1.f - g_ + 2.f * g_ * u.x);
            mu_p = (1.f + g_ * g_ - s * s) / (2.f * g_);
        }
        mu_p = clamp(mu_p, -1.f, 1.f);
        float sin_t = safe_sqrt(1.f - mu_p * mu_p);
        float phi = 2.f * kPi * u.y;
        Frame fr(-wi);
        PhaseSample ps;
        ps.wo = normalize(fr.to_world(Vec3(sin_t * std::cos(phi), sin_t * std::sin(phi), mu_p)));
        ps.pdf_w = hg(dot(wi, ps.wo));
        ps.weight = 1.f;
        return ps;
    }

private:
    float hg(float mu) const {
        float d = 1.f + g_ * g_ + 2.f * g_ * mu;
        return (1.f - g_ * g_) * kInv4Pi / (d * std::sqrt(d));
    }
    float g_;
};

}  // namespace

std::unique_ptr<PhaseFunction> make_phase(const std::string& type, float g) {
    if (type == "isotropic") return std::make_unique<IsotropicPhase>();
    if (type == "hg") {
        if (!(g > -1.f && g < 1.f))
            throw std::invalid_argument("phase 'hg': parameter 'g' must be in (-1, 1), got " + std::to_string(g));
        return std::make_unique<HenyeyGreensteinPhase>(g);
    }
    throw std::invalid_argument("phase: unknown type '" + type + "' (known: isotropic, hg)");
}

}  // namespace rm
