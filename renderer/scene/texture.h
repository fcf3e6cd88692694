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
//  rawconstant   value (1 or 3 floats), returned as it is (Mitsuba 3
//                src/textures/rawconstant.cpp: no colour conversion).
//  mesh_attribute  name, scale: a mesh's attribute (Mitsuba 3
//                src/textures/mesh_attribute.cpp; Mesh::eval_attribute):
//                vertex_* interpolated with the hit's barycentrics,
//                face_* constant per triangle, times scale; 1 channel
//                reads as grey. The mesh comes with the point
//                (SurfaceUv::attributes); the loader checks that every
//                shape it is used on has the attribute.
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
#include "scene/records.h"

namespace rm {

// A mesh's attributes (Mitsuba's Mesh::add_attribute): per vertex or per
// face, 1 or 3 channels, with the mesh's triangle indices to interpolate.
struct MeshAttribute {
    std::string name;  // vertex_* or face_*
    bool per_face = false;
    int channels = 1;
    std::vector<float> data;  // vertices (or faces) x channels
};
struct MeshAttributes {
    std::vector<MeshAttribute> list;
    const uint32_t* indices = nullptr;  // the mesh's, 3 per triangle
    const MeshAttribute* find(const std::string& name) const {
        for (const auto& a : list)
            if (a.name == name) return &a;
        return nullptr;
    }
};

struct TextureDesc {
    std::string type = "checkerboard";  // checkerboard | bitmap | rawconstant | mesh_attribute
    std::string id;                     // for error messages
    Color color0{0.4f}, color1{0.2f};   // checkerboard
    // to_uv, row-major 3x3 (the last row 0 0 1): uv' = M (u, v, 1).
    std::array<double, 9> to_uv{1, 0, 0, 0, 1, 0, 0, 0, 1};
    int width = 0, height = 0, channels = 3;  // bitmap
    std::vector<float> data;                  // bitmap: height rows of width pixels, channels floats each
    std::string filter_type = "bilinear";
    std::string wrap_mode = "repeat";
    std::vector<float> value;  // rawconstant: 1 or 3 floats
    std::string name;          // mesh_attribute
    float scale = 1.f;         // mesh_attribute
};

class Texture {
public:
    virtual ~Texture() = default;
    virtual Color eval(const SurfaceUv& uv) const = 0;
    virtual float eval_1(const SurfaceUv& uv) const = 0;
    virtual float mean() const = 0;
    // Cell weights over an nx x ny grid on [0, 1]^2 (rows along v) for
    // importance sampling uv (the projector's image plane): positive
    // wherever eval() may be non-zero in the cell, so that sampling by
    // them is unbiased; the default is one cell (uniform).
    virtual void sampling_grid(int& nx, int& ny, std::vector<double>& weights) const {
        nx = ny = 1;
        weights.assign(1, 1.0);
    }
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
    Color eval(const SurfaceUv& uv) const { return texture ? texture->eval(uv) : value; }
    // Mitsuba's Texture::mean() (see above); the channel average when plain.
    float mean() const { return texture ? texture->mean() : average(value); }
};

// A scalar parameter that may be textured (roughness and the like, read as
// Mitsuba reads them, Texture::eval_1): the plain value, or a texture.
struct TexturedFloat {
    float value = 0.f;
    std::shared_ptr<const Texture> texture;  // null: untextured

    TexturedFloat() = default;
    TexturedFloat(float v) : value(v) {}  // NOLINT: a plain value converts implicitly
    bool textured() const { return texture != nullptr; }
    float eval(const SurfaceUv& uv) const { return texture ? texture->eval_1(uv) : value; }
};

}  // namespace rm
