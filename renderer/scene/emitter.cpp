#include "scene/emitter.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "core/distribution.h"
#include "core/warp.h"
#include "scene/shape.h"
#include "scene/texture.h"

namespace rm {

namespace {

void check_color(const Color& c, const std::string& id, const char* name) {
    if (!is_finite(c) || min_component(c) < 0.f)
        throw std::invalid_argument("emitter '" + id + "': " + name + " must be finite and non-negative");
}

// Next event estimation towards a light at the point `pos` from `ref`: the
// direction, distance and delta density (the radiance is the light's to
// set, from `d2`, the squared distance); an empty sample (is_delta false)
// when ref is at pos.
DirectSample towards_point(const Vec3& pos, const Vec3& ref, float& d2) {
    DirectSample ds;
    const Vec3 v = pos - ref;
    d2 = length_sq(v);
    if (!(d2 > 0.f)) return ds;
    ds.dist = std::sqrt(d2);
    ds.d = v / ds.dist;
    ds.p = pos;
    ds.pdf_w = 1.f;
    ds.is_delta = true;
    return ds;
}

// The texture given for parameter `name` (null: none); any other textured
// parameter is refused by name.
std::shared_ptr<const Texture> texture_param(const EmitterDesc& d, const char* name) {
    for (const auto& [param, tex] : d.textures) {
        if (param != name)
            throw std::invalid_argument("emitter '" + d.id + "': parameter '" + param + "' cannot take a texture");
    }
    auto it = d.textures.find(name);
    if (it == d.textures.end()) return nullptr;
    try {
        return make_texture(it->second);
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("emitter '" + d.id + "': parameter '" + name + "': " + e.what());
    }
}

class AreaEmitter final : public Emitter {
public:
    AreaEmitter(const EmitterDesc& d, const Shape* shape) : shape_(shape), radiance_(d.radiance) {
        check_color(radiance_.value, d.id, "radiance");
        radiance_.texture = texture_param(d, "radiance");
        textured_ = radiance_.textured();
        if (!(shape_->area() > 0.f))
            throw std::invalid_argument("emitter '" + d.id + "': its shape '" + shape_->id + "' has zero area");
    }
    DirectSample sample_direct(const Vec3& ref, Vec2 u, float u_extra) const override {
        DirectSample ds;
        PositionSample ps;
        float cone_pdf_w = 0.f;
        bool by_direction = shape_->sample_direction(ref, u, ps, cone_pdf_w);  // the sphere's cone
        if (!by_direction) ps = shape_->sample_position(u, u_extra);
        Vec3 v = ps.p - ref;
        float d2 = length_sq(v);
        if (!(d2 > 0.f) || (!by_direction && ps.pdf_a <= 0.f)) return ds;
        float dist = std::sqrt(d2);
        ds.p = ps.p;
        ds.n = ps.n;
        ds.eps = ps.eps;
        ds.d = v / dist;
        ds.dist = dist;
        float cos_l = -dot(ps.n, ds.d);  // > 0 when the emitting side faces ref
        // Back side: emits nothing (pdf_w 0 marks a failed sample). A cone
        // sample is on the visible cap by construction (a rim sample's cosine
        // may round to <= 0; dropping it would lose its share).
        if (cos_l <= 0.f && !by_direction) return ds;
        // Area to solid angle: p_w = p_a d^2 / |cos theta_l| (Veach 1997, eq. 8.10).
        ds.pdf_w = by_direction ? cone_pdf_w : ps.pdf_a * d2 / cos_l;
        ds.radiance = radiance_.eval(ps.uv);
        return ds;
    }
    float pdf_direct(const Vec3& ref, const Vec3& p, const Vec3& n) const override {
        Vec3 v = p - ref;
        float d2 = length_sq(v);
        float cos_l = -dot(n, v) / std::sqrt(d2);
        if (cos_l <= 0.f || !(d2 > 0.f)) return 0.f;
        float pd = shape_->pdf_direction(ref, p);
        if (pd >= 0.f) return pd;
        return d2 / (cos_l * shape_->area());
    }
    Color eval(const Interaction& it, const Vec3& w) const override {
        return dot(it.sh.n, w) > 0.f ? radiance_.eval(it.uv) : Color(0.f);
    }
    // Position by area, direction cosine-weighted about the emitting side's
    // normal: weight = Le cos / (pdf_a cos / pi) = Le pi / pdf_a (PBR4 12.5.1).
    // A textured radiance is read at the point's uv; the point stays
    // uniform by area (an unbiased choice whatever the texture).
    EmissionSample sample_emission(Vec2 u_pos, float u_extra, Vec2 u_dir, const Vec3&, float) const override {
        EmissionSample es;
        PositionSample ps = shape_->sample_position(u_pos, u_extra);
        if (!(ps.pdf_a > 0.f)) return es;
        Vec3 local = warp::square_to_cosine_hemisphere(u_dir);
        if (!(local.z > 0.f)) return es;
        es.p = ps.p;
        es.n = ps.n;
        es.uv = ps.uv;
        es.eps = ps.eps;
        es.d = Frame(ps.n).to_world(local);
        es.pdf_a = ps.pdf_a;
        es.pdf_w = warp::square_to_cosine_hemisphere_pdf_w(local);
        es.weight = radiance_.eval(ps.uv) * (kPi / ps.pdf_a);
        return es;
    }
    Color emitted_towards(const EmissionSample& es, const Vec3& w) const override {
        float c = dot(es.n, w);
        if (!(c > 0.f) || !(es.pdf_a > 0.f)) return Color(0.f);
        return radiance_.eval(es.uv) * (c / es.pdf_a);
    }
    float pdf_emission_a(const Vec3&) const override { return 1.f / shape_->area(); }
    // pi L A: a cosine emitter on one side of every point (a texture's mean
    // for L: the light selection's weight, an estimate).
    float power(float) const override {
        const float l = radiance_.textured() ? radiance_.texture->mean() : luminance(radiance_.value);
        return l * kPi * shape_->area();
    }
    bool light_bounds(LightBounds& b) const override {
        b.lo = shape_->bbox_min();
        b.hi = shape_->bbox_max();
        shape_->normal_cone(b.w, b.cos_o);
        b.cos_e = 0.f;  // cos(pi / 2): emits over the hemisphere of each normal
        return true;
    }
    float pdf_emission_w(const Vec3& n, const Vec3& w) const override {
        float c = dot(n, w);
        return c > 0.f ? c * kInvPi : 0.f;
    }

private:
    const Shape* shape_;
    TexturedColor radiance_;
};

class PointEmitter final : public Emitter {
public:
    explicit PointEmitter(const EmitterDesc& d) : intensity_(d.intensity) {
        check_color(intensity_, d.id, "intensity");
        Transform xf;
        if (!xf.set(d.to_world.data())) throw std::invalid_argument("emitter '" + d.id + "': singular to_world");
        pos_ = xf.point(Vec3(0.f));
        delta_ = true;
    }
    DirectSample sample_direct(const Vec3& ref, Vec2, float) const override {
        float d2;
        DirectSample ds = towards_point(pos_, ref, d2);
        if (ds.is_delta) ds.radiance = intensity_ / d2;
        return ds;
    }
    // Delta position, direction uniform on the sphere: weight = I 4 pi.
    EmissionSample sample_emission(Vec2, float, Vec2 u_dir, const Vec3&, float) const override {
        EmissionSample es;
        es.p = pos_;
        es.d = warp::square_to_uniform_sphere(u_dir);
        es.pdf_a = 1.f;
        es.pdf_w = warp::square_to_uniform_sphere_pdf_w();
        es.weight = intensity_ * (4.f * kPi);
        return es;
    }
    Color emitted_towards(const EmissionSample&, const Vec3&) const override { return intensity_; }
    float pdf_emission_w(const Vec3&, const Vec3&) const override { return warp::square_to_uniform_sphere_pdf_w(); }
    float power(float) const override { return luminance(intensity_) * 4.f * kPi; }
    bool light_bounds(LightBounds& b) const override {
        b.lo = b.hi = pos_;
        b.w = Vec3(0.f, 0.f, 1.f);
        b.cos_o = -1.f;
        b.cos_e = 0.f;
        return true;
    }

private:
    Color intensity_;
    Vec3 pos_;
};

// A light at a point, the origin of to_world, whose intensity depends on the
// direction in to_world's frame: spot and projector. Next event estimation
// and the s = 1 connection of light paths read that intensity the same way;
// each light samples its own directions.
class LocalDeltaEmitter : public Emitter {
public:
    DirectSample sample_direct(const Vec3& ref, Vec2, float) const override {
        float d2;
        DirectSample ds = towards_point(pos_, ref, d2);
        if (ds.is_delta) ds.radiance = intensity_over(normalize(xf_.inv_vector(-ds.d)), d2);
        return ds;
    }
    Color emitted_towards(const EmissionSample&, const Vec3& w) const override {
        return intensity_over(normalize(xf_.inv_vector(w)), 1.f);
    }

protected:
    explicit LocalDeltaEmitter(const EmitterDesc& d) {
        if (!xf_.set(d.to_world.data())) throw std::invalid_argument("emitter '" + d.id + "': singular to_world");
        pos_ = xf_.point(Vec3(0.f));
        delta_ = true;
    }
    // The intensity towards the unit local direction `local`, divided by d2
    // (the squared distance of the point it reaches; 1: the intensity).
    virtual Color intensity_over(const Vec3& local, float d2) const = 0;
    Transform xf_;
    Vec3 pos_;
};

class SpotEmitter final : public LocalDeltaEmitter {
public:
    explicit SpotEmitter(const EmitterDesc& d) : LocalDeltaEmitter(d), intensity_(d.intensity) {
        check_color(intensity_, d.id, "intensity");
        texture_ = texture_param(d, "texture");
        textured_ = texture_ != nullptr;
        if (!(d.cutoff_angle > 0.f && d.cutoff_angle <= 180.f))
            throw std::invalid_argument("emitter '" + d.id + "': cutoff_angle must be in (0, 180] degrees");
        float beam = d.beam_width < 0.f ? 0.75f * d.cutoff_angle : d.beam_width;
        cutoff_ = d.cutoff_angle * kPi / 180.f;
        beam_ = std::min(beam * kPi / 180.f, cutoff_);
        uv_factor_ = std::tan(cutoff_);
    }
    // Mitsuba 3 spot falloff: 1 inside the beam, linear in angle to 0 at the
    // cutoff. Compared as angles from atan2(|xy|, z): the cosine of a 0.01
    // degree cutoff rounds to 1 in float and would light a cone 8x too wide.
    float falloff(const Vec3& local) const {
        float theta = std::atan2(std::sqrt(local.x * local.x + local.y * local.y), local.z);
        if (theta > cutoff_) return 0.f;
        if (theta <= beam_ || cutoff_ <= beam_) return 1.f;
        return (cutoff_ - theta) / (cutoff_ - beam_);
    }
    // The intensity towards the local direction `local` where the falloff
    // f is not 0: times the projected texture, if any, at Mitsuba 3's
    // direction_to_uv (src/emitters/spot.cpp): 1/2 + (x, y) / (2 z tan(cutoff)).
    Color intensity_towards(const Vec3& local, float f) const {
        if (!texture_ || !(f > 0.f)) return intensity_;
        const float s = 0.5f / (local.z * uv_factor_);
        return intensity_ * texture_->eval(Vec2(0.5f + local.x * s, 0.5f + local.y * s));
    }
    Color intensity_over(const Vec3& local, float d2) const override {
        const float f = falloff(local);
        return intensity_towards(local, f) * (f / d2);
    }
    // Direction uniform in the cone of the cutoff angle (as Mitsuba 3's spot),
    // weight = I falloff / pdf_w. 1 - cos(cutoff) is formed as 2 sin^2(c / 2):
    // the plain difference cancels to 0 for cutoffs below ~0.03 degrees.
    EmissionSample sample_emission(Vec2, float, Vec2 u, const Vec3&, float) const override {
        EmissionSample es;
        float omc_max = 2.f * sqr(std::sin(0.5f * cutoff_));
        float omc = u.x * omc_max;  // 1 - cos(theta), uniform: uniform in solid angle
        float sin_t = safe_sqrt(omc * (2.f - omc));
        float phi = 2.f * kPi * u.y;
        Vec3 local(sin_t * std::cos(phi), sin_t * std::sin(phi), 1.f - omc);
        es.p = pos_;
        es.d = normalize(xf_.vector(local));
        es.pdf_a = 1.f;
        es.pdf_w = 1.f / (2.f * kPi * omc_max);
        const float f = falloff(local);
        es.weight = intensity_towards(local, f) * (f * 2.f * kPi * omc_max);
        return es;
    }
    float pdf_emission_w(const Vec3&, const Vec3& w) const override {
        Vec3 local = normalize(xf_.inv_vector(w));
        float theta = std::atan2(std::sqrt(local.x * local.x + local.y * local.y), local.z);
        return theta <= cutoff_ ? 1.f / (2.f * kPi * 2.f * sqr(std::sin(0.5f * cutoff_))) : 0.f;
    }
    // I 2 pi ((1 - cos beam) + (cos beam - cos cutoff) / 2), as pbrt-v4's SpotLight::Phi.
    float power(float) const override {
        float cb = std::cos(beam_), cc = std::cos(cutoff_);
        // A projected texture scales it by its mean (an estimate: the light
        // selection's weight, not a value anything renders).
        const float t = texture_ ? texture_->mean() : 1.f;
        return t * luminance(intensity_) * 2.f * kPi * ((1.f - cb) + (cb - cc) / 2.f);
    }
    // Full intensity within the beam, falling off to 0 at the cutoff: the
    // spread beyond the beam widened by 1e-3 rad, so rounding never drops
    // a lit direction.
    bool light_bounds(LightBounds& b) const override {
        b.lo = b.hi = pos_;
        b.w = normalize(xf_.vector(Vec3(0.f, 0.f, 1.f)));
        b.cos_o = std::cos(beam_);
        b.cos_e = std::cos(std::min(cutoff_ - beam_ + 1e-3f, kPi));
        return true;
    }

private:
    Color intensity_;
    std::shared_ptr<const Texture> texture_;  // spot "texture"; null: none
    float uv_factor_ = 1.f;                   // tan(cutoff)
    float cutoff_, beam_;
};

// Mitsuba 3's projector (src/emitters/projector.cpp): the reciprocal of a
// perspective camera of horizontal field of view fov_x whose image, the
// `irradiance` texture, lies on the plane z = 1 of its local frame, with
// Mitsuba's sample-space uv: u = 1/2 - x / (2 z tan(fov_x / 2)),
// v = 1/2 - y / (2 z tan(fov_x / 2) / aspect), aspect = the texture's
// width / height (1 for a plain colour). Towards a local unit direction of
// cosine c = z inside the image, the intensity is
//     I = scale pi E(uv) / c^3,
// Mitsuba's sample_direction (E pi / (z_local^2 cos theta) arriving at a
// point of local depth z_local = dist c): a constant E lights the plane
// z = 1 with irradiance pi E, so a white diffuse plane there reflects E.
// Light paths sample uv by the texture's sampling grid (Texture::
// sampling_grid), the direction through the image-plane point: with the
// plane's area A = 4 tan^2(fov_x / 2) / aspect, dw = c^3 A duv, so
// pdf_w = pdf_uv / (A c^3) and weight = I / pdf_w = scale pi E A / pdf_uv,
// Mitsuba's sample_ray weight (pi m_sensor_area E / pdf).
class ProjectorEmitter final : public LocalDeltaEmitter {
public:
    explicit ProjectorEmitter(const EmitterDesc& d) : LocalDeltaEmitter(d), scale_(d.scale) {
        irradiance_.value = d.irradiance;
        check_color(irradiance_.value, d.id, "irradiance");
        irradiance_.texture = texture_param(d, "irradiance");
        textured_ = irradiance_.textured();
        if (!(scale_ >= 0.f && std::isfinite(scale_)))
            throw std::invalid_argument("emitter '" + d.id + "': scale must be finite and non-negative");
        if (!(d.fov_x > 0.f && d.fov_x < 180.f))
            throw std::invalid_argument("emitter '" + d.id + "': fov must be in (0, 180) degrees");
        if (!(d.aspect > 0.f && std::isfinite(d.aspect)))
            throw std::invalid_argument("emitter '" + d.id + "': aspect must be positive");
        tx_ = std::tan(0.5f * d.fov_x * kPi / 180.f);
        ty_ = tx_ / d.aspect;
        area_ = 4.f * tx_ * ty_;
        int nx = 1, ny = 1;
        std::vector<double> w(1, 1.0);
        if (irradiance_.texture) irradiance_.texture->sampling_grid(nx, ny, w);
        grid_ = PiecewiseConstant2D(w, nx, ny);
    }
    Color intensity_over(const Vec3& local, float d2) const override {
        Vec2 uv;
        if (!image_uv(local, uv)) return Color(0.f);
        const float c = local.z;
        return irradiance_.eval(uv) * (scale_ * kPi / (c * c * c * d2));
    }
    EmissionSample sample_emission(Vec2, float, Vec2 u, const Vec3&, float) const override {
        EmissionSample es;
        int i, j;
        double rx, ry, p;
        if (!grid_.sample(u, i, j, rx, ry, p)) return es;
        const Vec2 uv(float((double(i) + rx) / double(grid_.nx())), float((double(j) + ry) / double(grid_.ny())));
        const float pdf_uv = float(p * double(grid_.nx()) * double(grid_.ny()));
        const Vec3 local = normalize(Vec3((1.f - 2.f * uv.x) * tx_, (1.f - 2.f * uv.y) * ty_, 1.f));
        es.p = pos_;
        es.d = normalize(xf_.vector(local));
        es.pdf_a = 1.f;
        es.pdf_w = pdf_uv / (area_ * local.z * local.z * local.z);
        es.weight = irradiance_.eval(uv) * (scale_ * kPi * area_ / pdf_uv);
        return es;
    }
    float pdf_emission_w(const Vec3&, const Vec3& w) const override {
        const Vec3 local = normalize(xf_.inv_vector(w));
        Vec2 uv;
        if (!image_uv(local, uv)) return 0.f;
        const int i = std::min(int(uv.x * float(grid_.nx())), grid_.nx() - 1);
        const int j = std::min(int(uv.y * float(grid_.ny())), grid_.ny() - 1);
        const float pdf_uv = float(grid_.prob(i, j) * double(grid_.nx()) * double(grid_.ny()));
        return pdf_uv / (area_ * local.z * local.z * local.z);
    }
    // The flux: the integral of I over the image's directions, scale pi A
    // times the mean of E over uv (its luminance; a texture's mean()).
    float power(float) const override {
        const float e = irradiance_.textured() ? irradiance_.texture->mean() : luminance(irradiance_.value);
        return scale_ * kPi * area_ * e;
    }
    // The cone through the image's corners, widened by 1e-3 rad.
    bool light_bounds(LightBounds& b) const override {
        b.lo = b.hi = pos_;
        b.w = normalize(xf_.vector(Vec3(0.f, 0.f, 1.f)));
        b.cos_o = std::cos(std::min(std::atan(std::sqrt(tx_ * tx_ + ty_ * ty_)) + 1e-3f, kPi));
        b.cos_e = std::cos(1e-3f);
        return true;
    }

private:
    // Mitsuba's camera_to_sample for the local direction; false outside the image or behind.
    bool image_uv(const Vec3& local, Vec2& uv) const {
        if (!(local.z > 0.f)) return false;
        uv = Vec2(0.5f - local.x / (2.f * local.z * tx_), 0.5f - local.y / (2.f * local.z * ty_));
        return uv.x >= 0.f && uv.x <= 1.f && uv.y >= 0.f && uv.y <= 1.f;
    }
    TexturedColor irradiance_;
    float scale_ = 1.f;
    float tx_ = 1.f, ty_ = 1.f, area_ = 4.f;  // the image's half extents at z = 1, its area
    PiecewiseConstant2D grid_;                // over uv, from the texture's sampling grid
};

class DirectionalEmitter final : public Emitter {
public:
    explicit DirectionalEmitter(const EmitterDesc& d) : irradiance_(d.irradiance) {
        check_color(irradiance_, d.id, "irradiance");
        Transform xf;
        if (!xf.set(d.to_world.data())) throw std::invalid_argument("emitter '" + d.id + "': singular to_world");
        dir_ = normalize(xf.vector(Vec3(0, 0, 1)));
        if (!is_finite(dir_)) throw std::invalid_argument("emitter '" + d.id + "': direction is zero");
        delta_ = true;
        infinite_ = true;
    }
    DirectSample sample_direct(const Vec3&, Vec2, float) const override {
        DirectSample ds;
        ds.d = -dir_;
        ds.dist = kInf;
        ds.pdf_w = 1.f;
        ds.is_delta = true;
        ds.radiance = irradiance_;
        return ds;
    }
    // Origin uniform on a disk of the scene's bounding radius perpendicular to
    // the direction, outside the scene (pbrt-v4 DistantLight::SampleLe):
    // weight = E pi r^2.
    EmissionSample sample_emission(Vec2 u_pos, float, Vec2, const Vec3& c, float radius) const override {
        EmissionSample es;
        float r = infinite_disk_radius(radius);
        Vec2 q = warp::square_to_uniform_disk_concentric(u_pos);
        Frame fr(dir_);
        es.p = c + (fr.s * q.x + fr.t * q.y) * r - dir_ * r;
        es.d = dir_;
        es.pdf_a = 1.f / (kPi * r * r);
        es.pdf_w = 1.f;
        es.weight = irradiance_ * (kPi * r * r);
        return es;
    }

    float power(float radius) const override {
        float r = infinite_disk_radius(radius);
        return luminance(irradiance_) * kPi * r * r;
    }

private:
    Color irradiance_;
    Vec3 dir_;
};

class ConstantEmitter final : public Emitter {
public:
    explicit ConstantEmitter(const EmitterDesc& d) : radiance_(d.radiance) {
        check_color(radiance_, d.id, "radiance");
        environment_ = true;
        infinite_ = true;
    }
    DirectSample sample_direct(const Vec3&, Vec2 u, float) const override {
        DirectSample ds;
        ds.d = warp::square_to_uniform_sphere(u);
        ds.dist = kInf;
        ds.pdf_w = warp::square_to_uniform_sphere_pdf_w();
        ds.radiance = radiance_;
        return ds;
    }
    float pdf_direct(const Vec3&, const Vec3&, const Vec3&) const override {
        return warp::square_to_uniform_sphere_pdf_w();
    }
    float pdf_environment(const Vec3&) const override { return warp::square_to_uniform_sphere_pdf_w(); }
    Color eval_environment(const Vec3&) const override { return radiance_; }
    // Direction uniform on the sphere, origin uniform on the disk of the
    // scene's bounding radius perpendicular to it, outside the scene (pbrt-v4
    // UniformInfiniteLight::SampleLe): weight = L 4 pi * pi r^2.
    EmissionSample sample_emission(Vec2 u_pos, float, Vec2 u_dir, const Vec3& c, float radius) const override {
        EmissionSample es;
        float r = infinite_disk_radius(radius);
        es.d = warp::square_to_uniform_sphere(u_dir);
        Vec2 q = warp::square_to_uniform_disk_concentric(u_pos);
        Frame fr(es.d);
        es.p = c + (fr.s * q.x + fr.t * q.y) * r - es.d * r;
        es.pdf_a = 1.f / (kPi * r * r);
        es.pdf_w = warp::square_to_uniform_sphere_pdf_w();
        es.weight = radiance_ * (4.f * kPi * kPi * r * r);
        return es;
    }

    float power(float radius) const override {
        float r = infinite_disk_radius(radius);
        return luminance(radiance_) * 4.f * kPi * kPi * r * r;
    }

private:
    Color radiance_;
};

// Mitsuba 3's envmap: a latitude-longitude image around the scene. The
// parametrisation is Mitsuba's (src/emitters/envmap.cpp): local direction
// (sin phi sin theta, cos theta, -cos phi sin theta) with phi = 2 pi u,
// theta = pi v; the radiance is the bilinear interpolation of a grid whose
// vertex (i, j) is pixel (i, j) at u = (i + 1/2) / W, v = j / (H - 1),
// periodic in u (vertex W is vertex 0).
//
// Sampling: a piecewise-constant 2D distribution over the grid's cells (pbrt
// 3rd ed., sec. 13.6.7 and 14.2.4, "Piecewise-Constant 2D Distributions" and
// the infinite area light; pbrt-v4's PiecewiseConstant2D): cell (i, j)
// weighs the mean luminance of its corners times its solid angle, the sin
// theta Jacobian integrated exactly, dphi (cos theta_j - cos theta_j+1). In
// the cell, phi is uniform and cos theta is uniform, so the solid-angle
// density is constant there: p(cell) / (dphi dcos). A constant image thus
// samples the sphere uniformly, as `constant` does.
constexpr double kPiD = 3.14159265358979323846;

class EnvMapEmitter final : public Emitter {
public:
    explicit EnvMapEmitter(const EmitterDesc& d) : w_(d.env_width), h_(d.env_height), data_(d.env_data) {
        if (w_ < 2 || h_ < 3)
            throw std::invalid_argument("emitter '" + d.id + "': the environment map must be at least 2x3 pixels");
        if (data_.size() != size_t(w_) * size_t(h_) * 3)
            throw std::invalid_argument("emitter '" + d.id + "': environment map data has the wrong size");
        for (float v : data_)
            if (!std::isfinite(v) || v < 0.f)
                throw std::invalid_argument("emitter '" + d.id +
                                            "': environment map values must be finite and "
                                            "non-negative");
        if (!xf_.set(d.to_world.data())) throw std::invalid_argument("emitter '" + d.id + "': singular to_world");
        environment_ = true;
        infinite_ = true;
        // Cell weights, row by row, into the marginal (rows) and conditional (columns) CDFs.
        const int cw = w_, ch = h_ - 1;
        dphi_ = 2.0 * kPiD / double(w_);
        cos_.resize(size_t(h_));
        for (int j = 0; j < h_; ++j) cos_[size_t(j)] = std::cos(kPiD * double(j) / double(h_ - 1));
        std::vector<double> weights(size_t(ch) * size_t(cw));
        for (int j = 0; j < ch; ++j) {
            double dcos = cos_[size_t(j)] - cos_[size_t(j) + 1];
            for (int i = 0; i < cw; ++i) {
                double lum = 0.25 * (lum_at(i, j) + lum_at(i + 1, j) + lum_at(i, j + 1) + lum_at(i + 1, j + 1));
                weights[size_t(j) * size_t(cw) + size_t(i)] = lum * dcos * dphi_;
            }
        }
        dist_ = PiecewiseConstant2D(weights, cw, ch);
        total_ = dist_.total();
    }

    Color eval_environment(const Vec3& d) const override {
        double u, v;
        to_uv(d, u, v);
        // Mitsuba's lookup: shift by half a texel, wrap, scale to the grid.
        u -= 0.5 / double(w_);
        u -= std::floor(u);
        double x = u * double(w_), y = v * double(h_ - 1);
        int px = std::min(int(x), w_ - 1), py = std::min(int(y), h_ - 2);
        float fx = float(x - px), fy = float(y - py);
        Color c00 = pixel(px, py), c10 = pixel(px + 1, py), c01 = pixel(px, py + 1), c11 = pixel(px + 1, py + 1);
        return (c00 * (1.f - fx) + c10 * fx) * (1.f - fy) + (c01 * (1.f - fx) + c11 * fx) * fy;
    }

    float pdf_environment(const Vec3& d) const override {
        if (!(total_ > 0.0)) return 0.f;
        double u, v;
        to_uv(d, u, v);
        int i, j;
        cell_of(u, v, i, j);
        double p = dist_.prob(i, j);
        double dcos = cos_[size_t(j)] - cos_[size_t(j) + 1];
        return float(p / (dphi_ * dcos));
    }

    float pdf_direct(const Vec3& ref, const Vec3& p, const Vec3&) const override {
        return pdf_environment(normalize(p - ref));
    }

    DirectSample sample_direct(const Vec3&, Vec2 u, float) const override {
        DirectSample ds;
        ds.dist = kInf;
        float pdf;
        ds.d = sample_dir(u, pdf);
        if (!(pdf > 0.f)) return ds;
        ds.pdf_w = pdf;
        ds.radiance = eval_environment(ds.d);
        return ds;
    }

    // As ConstantEmitter's, with the direction from the image's distribution
    // (Mitsuba's envmap sample_ray): weight = L(w) pi r^2 / pdf_w(w).
    EmissionSample sample_emission(Vec2 u_pos, float, Vec2 u_dir, const Vec3& c, float radius) const override {
        EmissionSample es;
        float pdf;
        Vec3 w = sample_dir(u_dir, pdf);
        if (!(pdf > 0.f)) return es;
        float r = infinite_disk_radius(radius);
        es.d = -w;
        Vec2 q = warp::square_to_uniform_disk_concentric(u_pos);
        Frame fr(es.d);
        es.p = c + (fr.s * q.x + fr.t * q.y) * r - es.d * r;
        es.pdf_a = 1.f / (kPi * r * r);
        es.pdf_w = pdf;
        es.weight = eval_environment(w) * (kPi * r * r / pdf);
        return es;
    }

    // total_ is the integral of luminance over the sphere (the cell weights).
    float power(float radius) const override {
        float r = infinite_disk_radius(radius);
        return float(total_) * kPi * r * r;
    }

private:
    float lum_at(int i, int j) const {
        Color c = pixel(i, j);
        // Mitsuba's luminance() of linear sRGB (Rec. 709 Y).
        return 0.212671f * c.x + 0.715160f * c.y + 0.072169f * c.z;
    }
    Color pixel(int i, int j) const {
        const float* p = &data_[(size_t(j) * size_t(w_) + size_t(i % w_)) * 3];
        return Color(p[0], p[1], p[2]);
    }
    // World direction -> Mitsuba's (u, v): u = atan2(x, -z) / 2 pi, v = acos(y) / pi, local.
    void to_uv(const Vec3& d, double& u, double& v) const {
        Vec3 l = xf_.inv_vector(d);
        double len = std::sqrt(double(l.x) * l.x + double(l.y) * l.y + double(l.z) * l.z);
        double y = len > 0.0 ? std::clamp(double(l.y) / len, -1.0, 1.0) : 1.0;
        u = std::atan2(double(l.x), -double(l.z)) / (2.0 * kPiD);
        v = std::acos(y) / kPiD;
    }
    // The cell holding (u, v): column from the half-texel-shifted u, row from theta.
    void cell_of(double u, double v, int& i, int& j) const {
        double x = u * double(w_) - 0.5;
        x -= std::floor(x / double(w_)) * double(w_);
        i = std::clamp(int(x), 0, w_ - 1);
        j = std::clamp(int(v * double(h_ - 1)), 0, h_ - 2);
    }
    Vec3 sample_dir(Vec2 u, float& pdf) const {
        pdf = 0.f;
        int i, j;
        double rx, ry, p;
        if (!dist_.sample(u, i, j, rx, ry, p)) return Vec3(0, 0, 1);
        // In the cell: phi uniform, cos theta uniform.
        double phi = (double(i) + 0.5 + rx) * dphi_;
        double cos_t = cos_[size_t(j)] + ry * (cos_[size_t(j) + 1] - cos_[size_t(j)]);
        double sin_t = std::sqrt(std::max(0.0, 1.0 - cos_t * cos_t));
        Vec3 l(float(std::sin(phi) * sin_t), float(cos_t), float(-std::cos(phi) * sin_t));
        Vec3 d = normalize(xf_.vector(l));
        pdf = float(p / (dphi_ * (cos_[size_t(j)] - cos_[size_t(j) + 1])));
        return d;
    }

    int w_, h_;
    std::vector<float> data_;
    Transform xf_;
    double dphi_ = 0.0, total_ = 0.0;
    std::vector<double> cos_;   // cos theta of the grid's rows
    PiecewiseConstant2D dist_;  // over the grid's cells
};

}  // namespace

std::unique_ptr<Emitter> make_area_emitter(const EmitterDesc& desc, const Shape* shape) {
    auto e = std::make_unique<AreaEmitter>(desc, shape);
    e->id = desc.id;
    return e;
}

std::unique_ptr<Emitter> make_emitter(const EmitterDesc& desc) {
    if (desc.type != "spot" && desc.type != "projector" && !desc.textures.empty())
        throw std::invalid_argument("emitter '" + desc.id + "': parameter '" + desc.textures.begin()->first +
                                    "' cannot take a texture");
    std::unique_ptr<Emitter> e;
    if (desc.type == "point")
        e = std::make_unique<PointEmitter>(desc);
    else if (desc.type == "spot")
        e = std::make_unique<SpotEmitter>(desc);
    else if (desc.type == "projector")
        e = std::make_unique<ProjectorEmitter>(desc);
    else if (desc.type == "directional")
        e = std::make_unique<DirectionalEmitter>(desc);
    else if (desc.type == "constant")
        e = std::make_unique<ConstantEmitter>(desc);
    else if (desc.type == "envmap")
        e = std::make_unique<EnvMapEmitter>(desc);
    else
        throw std::invalid_argument("emitter '" + desc.id + "': unknown type '" + desc.type + "'");
    e->id = desc.id;
    return e;
}

}  // namespace rm
