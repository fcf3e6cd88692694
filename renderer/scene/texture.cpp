#include "scene/texture.h"

#include <algorithm>
#include <stdexcept>

namespace rm {

namespace {

[[noreturn]] void fail(const TextureDesc& d, const std::string& param, const std::string& why) {
    throw std::invalid_argument("texture '" + d.id + "' (type '" + d.type + "'): parameter '" + param + "' " + why);
}

// The 2D affine map to_uv, in float as Mitsuba applies it (ScalarTransform3f).
struct UvMap {
    float m[6] = {1, 0, 0, 0, 1, 0};
    bool identity = true;
    explicit UvMap(const std::array<double, 9>& a) {
        for (int i = 0; i < 6; ++i) m[i] = float(a[size_t(i)]);
        identity = a == std::array<double, 9>{1, 0, 0, 0, 1, 0, 0, 0, 1};
    }
    Vec2 apply(Vec2 uv) const {
        if (identity) return uv;
        return Vec2(m[0] * uv.x + m[1] * uv.y + m[2], m[3] * uv.x + m[4] * uv.y + m[5]);
    }
    // A gradient with respect to the mapped uv', taken back to uv (chain rule).
    Vec2 pull_back(Vec2 g) const {
        if (identity) return g;
        return Vec2(g.x * m[0] + g.y * m[3], g.x * m[1] + g.y * m[4]);
    }
};

void check_to_uv(const TextureDesc& d) {
    for (double x : d.to_uv)
        if (!std::isfinite(x)) fail(d, "to_uv", "must be finite");
    if (d.to_uv[6] != 0 || d.to_uv[7] != 0 || d.to_uv[8] != 1) fail(d, "to_uv", "must be affine (last row 0 0 1)");
}

class CheckerboardTexture final : public Texture {
public:
    CheckerboardTexture(const Color& c0, const Color& c1, const UvMap& map) : c0_(c0), c1_(c1), map_(map) {}
    Color eval(const SurfaceUv& uv) const override {
        const Vec2 p = map_.apply(uv);
        const bool mu = p.x - std::floor(p.x) > 0.5f, mv = p.y - std::floor(p.y) > 0.5f;
        return mu == mv ? c0_ : c1_;
    }
    float eval_1(const SurfaceUv& uv) const override {
        const Vec2 p = map_.apply(uv);
        const bool mu = p.x - std::floor(p.x) > 0.5f, mv = p.y - std::floor(p.y) > 0.5f;
        return mu != mv ? average(c0_) : average(c1_);
    }
    float mean() const override { return 0.5f * (average(c0_) + average(c1_)); }
    Vec2 eval_1_grad(Vec2) const override { return Vec2(0.f, 0.f); }

private:
    Color c0_, c1_;
    UvMap map_;
};

enum class Wrap { Repeat, Mirror, Clamp };

// Dr.Jit's dr::Texture::wrap(), one index: repeat is the index modulo n;
// mirror reflects at every edge (period 2n: 0..n-1, then n-1..0); clamp stops
// at the edges.
inline int wrap_index(int i, int n, Wrap w) {
    if (w == Wrap::Clamp) return std::min(std::max(i, 0), n - 1);
    if (w == Wrap::Repeat) return ((i % n) + n) % n;
    const int m = ((i % (2 * n)) + 2 * n) % (2 * n);
    return m < n ? m : 2 * n - 1 - m;
}

class BitmapTexture final : public Texture {
public:
    BitmapTexture(const TextureDesc& d, const UvMap& map, Wrap wrap, bool bilinear)
        : w_(d.width), h_(d.height), ch_(d.channels), data_(d.data), map_(map), wrap_(wrap), bilinear_(bilinear) {
        double sum = 0;
        for (int i = 0; i < w_ * h_; ++i) sum += double(luminance(texel_at(i)));
        mean_ = float(sum / double(w_ * h_));
    }

    Color eval(const SurfaceUv& uv) const override {
        const Vec2 p = map_.apply(uv);
        if (!bilinear_) {
            const int x = wrap_index(int(std::floor(p.x * float(w_))), w_, wrap_);
            const int y = wrap_index(int(std::floor(p.y * float(h_))), h_, wrap_);
            return texel(x, y);
        }
        const Footprint b = footprint(p);
        const int xa = b.xa, xb = b.xb, ya = b.ya, yb = b.yb;
        const float w0x = b.w0x, w1x = b.w1x, w0y = b.w0y, w1y = b.w1y;
        const Color f0 = texel(xa, ya) * w0x + texel(xb, ya) * w1x;
        const Color f1 = texel(xa, yb) * w0x + texel(xb, yb) * w1x;
        return f0 * w0y + f1 * w1y;
    }
    float eval_1(const SurfaceUv& uv) const override {
        const Color c = eval(uv);
        return ch_ == 1 ? c.x : luminance(c);
    }
    float mean() const override { return mean_; }
    // Per texel, where to_uv is the identity: its channel mean (nearest),
    // or the largest over the texels a bilinear lookup in it blends, its
    // wrapped 3x3 neighbourhood (bilinear), so that no lit uv has a zero
    // weight. Under another to_uv: uniform.
    void sampling_grid(int& nx, int& ny, std::vector<double>& w) const override {
        if (!map_.identity) return Texture::sampling_grid(nx, ny, w);
        nx = w_;
        ny = h_;
        w.assign(size_t(w_) * size_t(h_), 0.0);
        for (int y = 0; y < h_; ++y)
            for (int x = 0; x < w_; ++x) {
                double m = 0.0;
                const int r = bilinear_ ? 1 : 0;
                for (int dy = -r; dy <= r; ++dy)
                    for (int dx = -r; dx <= r; ++dx)
                        m = std::max(
                            m, double(average(texel(wrap_index(x + dx, w_, wrap_), wrap_index(y + dy, h_, wrap_)))));
                w[size_t(y) * size_t(w_) + size_t(x)] = m;
            }
    }

    // The bilinear interpolant's derivatives: along x the difference of the
    // two columns, weighted by the row weights, times the resolution (each
    // texel spans 1 / res of uv); likewise along y.
    Vec2 eval_1_grad(Vec2 uv) const override {
        if (!bilinear_) return Vec2(0.f, 0.f);
        const Footprint b = footprint(map_.apply(uv));
        const int xa = b.xa, xb = b.xb, ya = b.ya, yb = b.yb;
        const float w0x = b.w0x, w1x = b.w1x, w0y = b.w0y, w1y = b.w1y;
        const float f00 = value_1(xa, ya), f10 = value_1(xb, ya), f01 = value_1(xa, yb), f11 = value_1(xb, yb);
        const Vec2 g(((f10 - f00) * w0y + (f11 - f01) * w1y) * float(w_),
                     ((f01 - f00) * w0x + (f11 - f10) * w1x) * float(h_));
        return map_.pull_back(g);
    }

private:
    // A bilinear lookup's four texels (columns xa, xb, rows ya, yb, wrapped)
    // and their weights, texel centres at (i + 1/2) / res: eval and
    // eval_1_grad read the same footprint.
    struct Footprint {
        int xa, xb, ya, yb;
        float w0x, w1x, w0y, w1y;
    };
    Footprint footprint(const Vec2& p) const {
        const float fx = p.x * float(w_) - 0.5f, fy = p.y * float(h_) - 0.5f;
        const float x0f = std::floor(fx), y0f = std::floor(fy);
        Footprint b;
        b.w1x = fx - x0f;
        b.w1y = fy - y0f;
        b.w0x = 1.f - b.w1x;
        b.w0y = 1.f - b.w1y;
        const int x0 = int(x0f), y0 = int(y0f);
        b.xa = wrap_index(x0, w_, wrap_);
        b.xb = wrap_index(x0 + 1, w_, wrap_);
        b.ya = wrap_index(y0, h_, wrap_);
        b.yb = wrap_index(y0 + 1, h_, wrap_);
        return b;
    }

    // A texel read as one number, as eval_1 reads the interpolated colour
    // (luminance is linear, so interpolating it is the same).
    float value_1(int x, int y) const {
        const Color c = texel(x, y);
        return ch_ == 1 ? c.x : luminance(c);
    }
    Color texel_at(int i) const {
        const float* v = &data_[size_t(i) * size_t(ch_)];
        return ch_ == 1 ? Color(v[0]) : Color(v[0], v[1], v[2]);
    }
    Color texel(int x, int y) const { return texel_at(y * w_ + x); }

    int w_, h_, ch_;
    std::vector<float> data_;
    UvMap map_;
    Wrap wrap_;
    bool bilinear_;
    float mean_ = 0.f;
};

class RawConstantTexture final : public Texture {
public:
    explicit RawConstantTexture(const std::vector<float>& v)
        : value_(v.size() == 1 ? Color(v[0]) : Color(v[0], v[1], v[2])) {}
    Color eval(const SurfaceUv&) const override { return value_; }
    float eval_1(const SurfaceUv&) const override { return average(value_); }
    float mean() const override { return average(value_); }
    Vec2 eval_1_grad(Vec2) const override { return Vec2(0.f, 0.f); }

private:
    Color value_;
};

class MeshAttributeTexture final : public Texture {
public:
    MeshAttributeTexture(std::string name, float scale) : name_(std::move(name)), scale_(scale) {}
    // Mitsuba 3's Mesh::eval_attribute: a vertex attribute interpolated as
    // the position is (b0 v0 + b1 v1 + b2 v2), a face attribute read at the
    // triangle; 1 channel broadcast to grey. Black off a mesh that has it
    // (the loader refuses such a scene).
    Color eval(const SurfaceUv& uv) const override {
        const MeshAttribute* a = uv.attributes && uv.prim >= 0 ? uv.attributes->find(name_) : nullptr;
        if (!a) return Color(0.f);
        auto at = [a](size_t k) {
            const float* v = &a->data[k * size_t(a->channels)];
            return a->channels == 1 ? Color(v[0]) : Color(v[0], v[1], v[2]);
        };
        if (a->per_face) return at(size_t(uv.prim)) * scale_;
        const uint32_t* f = uv.attributes->indices + 3 * size_t(uv.prim);
        const float b1 = uv.bary.x, b2 = uv.bary.y, b0 = 1.f - b1 - b2;
        return (at(f[0]) * b0 + at(f[1]) * b1 + at(f[2]) * b2) * scale_;
    }
    float eval_1(const SurfaceUv& uv) const override { return average(eval(uv)); }
    // Mitsuba's has none (Texture::mean() is not implemented there); the
    // value only weighs lobe and light choices, so a mid grey stands in.
    float mean() const override { return 0.5f * scale_; }
    // No uv gradient: the attribute varies over the triangle's barycentrics,
    // which a bump map's uv derivative does not see (a bumpmap over it is flat).
    Vec2 eval_1_grad(Vec2) const override { return Vec2(0.f, 0.f); }

private:
    std::string name_;
    float scale_;
};

}  // namespace

std::shared_ptr<const Texture> make_texture(const TextureDesc& d) {
    check_to_uv(d);
    const UvMap map(d.to_uv);
    if (d.type == "checkerboard") {
        for (const auto& [name, c] : {std::pair<const char*, Color>{"color0", d.color0}, {"color1", d.color1}})
            if (!is_finite(c) || min_component(c) < 0.f) fail(d, name, "must be finite and non-negative");
        return std::make_shared<CheckerboardTexture>(d.color0, d.color1, map);
    }
    if (d.type == "bitmap") {
        if (d.channels != 1 && d.channels != 3) fail(d, "data", "must have 1 or 3 channels");
        if (d.width < 1 || d.height < 1) fail(d, "data", "must hold at least one pixel");
        if (d.data.size() != size_t(d.width) * size_t(d.height) * size_t(d.channels))
            fail(d, "data", "holds " + std::to_string(d.data.size()) + " floats, not width x height x channels");
        for (float v : d.data)
            if (!std::isfinite(v) || v < 0.f) fail(d, "data", "must be finite and non-negative");
        Wrap wrap;
        if (d.wrap_mode == "repeat")
            wrap = Wrap::Repeat;
        else if (d.wrap_mode == "mirror")
            wrap = Wrap::Mirror;
        else if (d.wrap_mode == "clamp")
            wrap = Wrap::Clamp;
        else
            fail(d, "wrap_mode", "must be \"repeat\", \"mirror\" or \"clamp\", got \"" + d.wrap_mode + "\"");
        if (d.filter_type != "bilinear" && d.filter_type != "nearest")
            fail(d, "filter_type", "must be \"bilinear\" or \"nearest\", got \"" + d.filter_type + "\"");
        return std::make_shared<BitmapTexture>(d, map, wrap, d.filter_type == "bilinear");
    }
    if (d.type == "rawconstant") {
        if (d.value.size() != 1 && d.value.size() != 3) fail(d, "value", "must hold 1 or 3 floats");
        for (float v : d.value)
            if (!std::isfinite(v) || v < 0.f) fail(d, "value", "must be finite and non-negative");
        return std::make_shared<RawConstantTexture>(d.value);
    }
    if (d.type == "mesh_attribute") {
        if (d.name.rfind("vertex_", 0) != 0 && d.name.rfind("face_", 0) != 0)
            fail(d, "name", "must start with \"vertex_\" or \"face_\", got \"" + d.name + "\"");
        if (!std::isfinite(d.scale)) fail(d, "scale", "must be finite");
        return std::make_shared<MeshAttributeTexture>(d.name, d.scale);
    }
    throw std::invalid_argument("texture '" + d.id + "': unknown type '" + d.type + "'");
}

}  // namespace rm
