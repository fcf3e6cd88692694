// Textures: colours that vary over a surface, evaluated at a hit's texture
// coordinates (Interaction::uv), with Mitsuba 3's plugins and semantics.
//
// Parameters (TextureDesc fields; the Python loader decodes image files,
// applies sRGB -> linear unless `raw`, and fills in Mitsuba's defaults):
//  checkerboard  color0 [0.4], color1 [0.2], to_uv (a 3x3 affine map of uv).
//                Mitsuba 3 src/textures/checkerboard.cpp: with (u', v') =
//                to_uv(uv), color0 where (frac(u') > 1/2) == (frac(v') > 1/2),
//                color1 elsewhere (its eval / eval_3 rule for colours).
//  bitmap        width x height pixels of 1 or 3 channels, row 0 at v = 0
//                (as Mitsuba 3 stores an image: no flip), filter_type
//                (bilinear | nearest), wrap_mode (repeat | mirror | clamp),
//                to_uv. Mitsuba 3 src/textures/bitmap.cpp with Dr.Jit's
//                dr::Texture lookup: bilinear reads the four texels around
//                uv * res - 1/2; nearest the texel floor(uv * res); each
//                index wrapped on its own. A 1-channel image is grey.
//  rawconstant   value (a float or a 3-vector, kept as given: Mitsuba 3
//                src/textures/rawconstant.cpp), in color0 with `channels`.
// eval_1() is a texture read as one number (Mitsuba's Texture::eval_1, which
// roughness parameters use): a bitmap's single channel, or the luminance
// (Rec. 709 weights) of its three; for a checkerboard, the channel mean of
// a colour, with the squares the other way round (Mitsuba 3.9.1's
// checkerboard keeps its "legacy scalar convention" there: color0 where
// (frac(u') > 1/2) != (frac(v') > 1/2); measured with mitsuba.load_dict).
// mean() is what Mitsuba's Texture::mean() gives (the BSDFs that pick a
// lobe by albedo use it): the channel average of a constant colour, the
// average of the two colours' means for a checkerboard, the mean luminance
// (Rec. 709 weights) of a bitmap.
#pragma once
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "core/math.h"
#include "core/spectrum.h"

namespace rm {

struct TextureDesc {
    std::string type = "checkerboard";  // checkerboard | bitmap | rawconstant
    std::string id;                     // for error messages
    Color color0{0.4f}, color1{0.2f};   // checkerboard
    // to_uv, row-major 3x3 (the last row 0 0 1): uv' = M (u, v, 1).
    std::array<double, 9> to_uv{1, 0, 0, 0, 1, 0, 0, 0, 1};
    int width = 0, height = 0, channels = 3;  // bitmap
    std::vector<float> data;                  // bitmap: height rows of width pixels, channels floats each
    std::string filter_type = "bilinear";
    std::string wrap_mode = "repeat";
};

class Texture {
public:
    virtual ~Texture() = default;
    virtual Color eval(Vec2 uv) const = 0;
    virtual float eval_1(Vec2 uv) const = 0;
    virtual float mean() const = 0;
    // The uv gradient of eval_1 (Mitsuba's Texture::eval_1_grad, which
    // bumpmap reads): d eval_1 / du, d eval_1 / dv, to_uv's Jacobian
    // included; 0 where the texture is piecewise constant (checkerboard,
    // a nearest-filtered bitmap, as Mitsuba's). Measured against
    // mitsuba.load_dict in tests/test_normalmap.py.
    virtual Vec2 eval_1_grad(Vec2 uv) const = 0;
};

// Throws std::invalid_argument naming the texture (desc.id) and the
// offending parameter on bad values.
std::shared_ptr<const Texture> make_texture(const TextureDesc& desc);

// A colour parameter that may be textured: the plain value, or a texture.
// The untextured case costs one predictable branch and no virtual call, and
// returns the value itself (so untextured scenes render bit for bit as
// before textures existed).
struct TexturedColor {
    Color value{0.f};
    std::shared_ptr<const Texture> texture;  // null: untextured

    TexturedColor() = default;
    TexturedColor(const Color& v) : value(v) {}  // NOLINT: a plain colour converts implicitly
    bool textured() const { return texture != nullptr; }
    Color eval(Vec2 uv) const { return texture ? texture->eval(uv) : value; }
    // Mitsuba's Texture::mean() (see above); the channel average when plain.
    float mean() const { return texture ? texture->mean() : average(value); }
};

}  // namespace rm
