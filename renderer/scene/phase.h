// Phase functions of participating media: isotropic and Henyey-Greenstein.
// Directions follow the BSDF convention (both point away from the scattering
// point; wi towards the previous vertex), so forward scattering (g > 0)
// favours wo = -wi. Normalised over the sphere; eval == pdf (Mitsuba 3's
// `isotropic` and `hg` plugins).
#pragma once
#include <memory>
#include <string>

#include "core/math.h"

namespace rm {

struct PhaseSample {
    Vec3 wo{0, 0, 1};
    float weight = 0.f;  // eval / pdf_w: 1 for these exactly sampled phase functions
    float pdf_w = 0.f;
};

class PhaseFunction {
public:
    virtual ~PhaseFunction() = default;
    virtual PhaseSample sample(const Vec3& wi, Vec2 u) const = 0;
    virtual float eval(const Vec3& wi, const Vec3& wo) const = 0;
    float pdf_w(const Vec3& wi, const Vec3& wo) const { return eval(wi, wo); }
};

// type "isotropic" or "hg" (g in (-1, 1)); throws std::invalid_argument naming the parameter.
std::unique_ptr<PhaseFunction> make_phase(const std::string& type, float g);

}  // namespace rm
