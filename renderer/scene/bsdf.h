// BSDF interface. Directions are in the local shading frame (z = shading
// normal), both pointing away from the surface: wi towards the previous vertex
// (the camera side in radiance transport), wo the sampled/queried direction.
// As in Mitsuba 3, eval() returns f(wi, wo) * |cos theta_o| (the foreshortening
// factor is included) and a sample's weight is eval / pdf_w.
#pragma once
#include <cstdint>
#include <memory>

#include "core/math.h"
#include "core/spectrum.h"
#include "scene/desc.h"

namespace rm {

enum BsdfFlags : uint32_t {
    kDiffuseReflection = 1u << 0,
    kDiffuseTransmission = 1u << 1,
    kGlossyReflection = 1u << 2,
    kGlossyTransmission = 1u << 3,
    kDeltaReflection = 1u << 4,
    kDeltaTransmission = 1u << 5,
    kNull = 1u << 6,  // index-matched medium boundary: passes light unchanged
    kDelta = kDeltaReflection | kDeltaTransmission | kNull,
    kSmooth = kDiffuseReflection | kDiffuseTransmission | kGlossyReflection | kGlossyTransmission,
    kTransmission = kDiffuseTransmission | kGlossyTransmission | kDeltaTransmission | kNull,
};

// Radiance: light flows from wo to wi (camera paths). Importance: the adjoint
// (light paths); non-symmetric BSDFs (refraction) differ by (eta)^2.
enum class TransportMode : uint8_t { Radiance, Importance };

// What a query needs to know besides the directions: the transport mode,
// and the hit's texture coordinates for textured parameters (texture.h).
// The uv travels here, not in the BSDF object, so that one BSDF serves every
// hit without a per-hit copy or allocation; every caller that queries the
// BSDF of a surface hit sets it from Interaction::uv (untextured BSDFs never
// read it).
struct BsdfContext {
    TransportMode mode = TransportMode::Radiance;
    SurfaceUv uv{};
};

struct BsdfSample {
    Vec3 wo{0, 0, 1};            // sampled direction, local frame
    Color weight{0.f};           // eval / pdf_w, selection probabilities included; 0 = failed
    float pdf_w = 0.f;           // solid-angle density; for a delta lobe the probability of picking it
    bool is_delta = false;       // the sampled lobe is a Dirac delta
    uint32_t sampled_flags = 0;  // the BsdfFlags bit of the lobe that was sampled
    float eta = 1.f;             // relative IOR crossed (eta_t / eta_i) on refraction, 1 otherwise
};

class Bsdf {
public:
    virtual ~Bsdf() = default;
    // u1 picks a lobe, u2 samples within it.
    virtual BsdfSample sample(const BsdfContext& ctx, const Vec3& wi, float u1, Vec2 u2) const = 0;
    // Non-delta lobes only: f * |cos theta_o|.
    virtual Color eval(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const = 0;
    // Non-delta lobes only, solid angle; consistent with sample() (including lobe selection).
    virtual float pdf_w(const BsdfContext& ctx, const Vec3& wi, const Vec3& wo) const = 0;
    // A kNull lobe's straight-through fraction at incidence |cos theta|
    // (Mitsuba 3's eval_null_transmission): what a shadow ray keeps when it
    // passes the surface. 0 for BSDFs without such a lobe.
    virtual Color null_transmission(float cos_theta) const {
        (void)cos_theta;
        return Color(0.f);
    }
    uint32_t flags() const { return flags_; }
    bool has_smooth() const { return (flags_ & kSmooth) != 0; }
    bool is_pure_delta() const { return (flags_ & kSmooth) == 0; }
    // Some parameter is a texture: the value depends on BsdfContext::uv.
    bool textured() const { return textured_; }
    // The value depends on the tangent direction (alpha_u != alpha_v, or
    // textured alphas): the shading frame's tangent must then follow the
    // surface's dp/du, as Mitsuba's does (Shape::uv_frame).
    bool anisotropic() const { return anisotropic_; }

protected:
    uint32_t flags_ = 0;
    bool textured_ = false;
    bool anisotropic_ = false;
};

// Builds a BSDF from its description; throws std::invalid_argument naming the
// BSDF (desc.id) and the offending parameter on bad values.
std::unique_ptr<Bsdf> make_bsdf(const BsdfDesc& desc);

}  // namespace rm
