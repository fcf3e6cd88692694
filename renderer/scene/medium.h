// Participating media: homogeneous (Mitsuba 3's `homogeneous`), RGB-varying
// extinction and albedo, with an isotropic or Henyey-Greenstein phase function.
// The volume rendering equation (Kajiya 1986; the seed's form):
//   (w . grad) L = sigma_a L_e - sigma_t L + sigma_s int p(w', w) L(w') dw',
// so along a ray through a homogeneous medium the transmittance is
// Tr(t) = exp(-sigma_t t) (Beer-Lambert) per colour channel.
#pragma once
#include <cmath>
#include <memory>
#include <string>

#include "core/spectrum.h"
#include "scene/desc.h"
#include "scene/phase.h"

namespace rm {

class Medium {
public:
    // Throws std::invalid_argument naming the medium for a bad parameter.
    explicit Medium(const MediumDesc& d);
    std::string id;
    Color sigma_t, sigma_s;
    std::unique_ptr<PhaseFunction> phase;

    // Beer-Lambert transmittance over a distance t (t may be infinite: a
    // channel with sigma_t = 0 keeps 1 there, the others 0).
    Color transmittance(float t) const {
        return {tr1(sigma_t.x, t), tr1(sigma_t.y, t), tr1(sigma_t.z, t)};
    }

private:
    static float tr1(float s, float t) { return s > 0.f ? std::exp(-s * t) : 1.f; }
};

}  // namespace rm
