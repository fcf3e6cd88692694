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
#include "scene/records.h"

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
    // Interaction::n_base: where a normal or bump map perturbed the frame,
    // the unperturbed shading normal in the (perturbed) local frame.
    Vec3 n_base{0.f, 0.f, 1.f};

    // The context of a query at the surface hit `it`.
    static BsdfContext at(const Interaction& it, TransportMode mode = TransportMode::Radiance) {
        return BsdfContext{mode, it.uv, it.n_base};
    }
    void set(const Interaction& it) {
        uv = it.uv;
        n_base = it.n_base;
    }
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
    // ctx.uv: where (mask's opacity texture).
    virtual Color null_transmission(const BsdfContext& ctx, float cos_theta) const {
        (void)ctx;
        (void)cos_theta;
        return Color(0.f);
    }
    // Normal and bump mapping (normalmap, bumpmap, or a BSDF nesting one):
    // replaces the hit's shading frame it.sh by the perturbed one (and sets
    // it.n_base), from it.uv, it.dp_du, it.dp_dv, it.n and, with
    // flip_invalid_normals, it.wi. Scene::intersect calls it on every
    // hit of a shape with such a BSDF, so that every estimator's local
    // directions, and the adjoint shading-normal correction of light paths
    // (shading_correction, Veach 1997 sec. 5.3), see the perturbed normal,
    // as pbrt-v4 applies its normal and bump maps to the intersection's
    // shading geometry (NormalMap, BumpMap in materials.h).
    virtual void perturb_frame(Interaction& it) const { (void)it; }
    bool perturbs_frame() const { return perturbs_frame_; }
    // The perturbed frame depends on the direction the ray arrived from
    // (flip_invalid_normals): right for camera paths, not for light paths.
    bool frame_follows_wi() const { return frame_follows_wi_; }
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
    bool perturbs_frame_ = false;
    bool frame_follows_wi_ = false;
};

// Builds a BSDF from its description; throws std::invalid_argument naming the
// BSDF (desc.id) and the offending parameter on bad values.
std::unique_ptr<Bsdf> make_bsdf(const BsdfDesc& desc);

}  // namespace rm
