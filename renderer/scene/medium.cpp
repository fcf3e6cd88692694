#include "scene/medium.h"

#include <stdexcept>

namespace rm {

Medium::Medium(const MediumDesc& d) : id(d.id) {
    const std::string who = "medium '" + d.id + "'";
    if (d.type != "homogeneous")
        throw std::invalid_argument(who + ": type '" + d.type + "' is not implemented yet (known: homogeneous)");
    for (int c = 0; c < 3; ++c) {
        if (!(d.sigma_t[c] >= 0.f) || !std::isfinite(d.sigma_t[c]))
            throw std::invalid_argument(who + ": sigma_t must be finite and >= 0, got " + std::to_string(d.sigma_t[c]));
        if (!(d.albedo[c] >= 0.f && d.albedo[c] <= 1.f))
            throw std::invalid_argument(who + ": albedo must lie in [0, 1], got " + std::to_string(d.albedo[c]));
    }
    sigma_t = d.sigma_t;
    sigma_s = d.sigma_t * d.albedo;
    try {
        phase = make_phase(d.phase, d.g);
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(who + ": " + e.what());
    }
}

}  // namespace rm
