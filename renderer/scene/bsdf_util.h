// Helpers shared by the BSDF plugins (bsdf.cpp and the larger plugins in
// files of their own, e.g. bsdf_principled.cpp): the validation of a
// BsdfDesc's parameters, with errors naming the BSDF and the parameter, the
// textured parameters, and the "no NaN, no Inf" guards of a sample.
#pragma once
#include <cmath>
#include <initializer_list>
#include <memory>
#include <string>

#include "scene/bsdf.h"
#include "scene/texture.h"

namespace rm::bsdf_util {

// a, negated when b's sign bit is set (Mitsuba's mulsign: -0 counts as negative).
inline float mulsign(float a, float b) { return std::signbit(b) ? -a : a; }
inline Vec3 mulsign(const Vec3& v, float b) { return std::signbit(b) ? -v : v; }

// The last line of defence of "no NaN, no Inf": a sample that is not finite
// and positive in every part becomes a failed sample.
inline BsdfSample sanitize(BsdfSample bs) {
    if (!(bs.pdf_w > 0.f) || !std::isfinite(bs.pdf_w) || !is_finite(bs.weight) || !is_finite(bs.wo) ||
        !std::isfinite(bs.eta) || min_component(bs.weight) < 0.f)
        return BsdfSample{};
    return bs;
}
inline Color finite_or_zero(const Color& c) { return is_finite(c) ? c : Color(0.f); }
inline float finite_or_zero(float v) { return std::isfinite(v) ? v : 0.f; }

// Throws std::invalid_argument naming the BSDF (d.id, d.type) and `param`.
[[noreturn]] void fail(const BsdfDesc& d, const std::string& param, const std::string& why);
void check_color(const BsdfDesc& d, const char* name, const Color& c);
// The parameter `name` of value `plain`, or its texture when d.textures has one.
TexturedColor textured(const BsdfDesc& d, const char* name, const Color& plain);
// A scalar parameter's texture (read with eval_1), or null when it has none.
std::shared_ptr<const Texture> texture_of(const BsdfDesc& d, const char* name);
// Only the parameters in `allowed` may take a texture.
void check_textured_names(const BsdfDesc& d, std::initializer_list<const char*> allowed);

}  // namespace rm::bsdf_util
