#include "scene/emitter.h"

#include <stdexcept>

#include "core/warp.h"
#include "scene/shape.h"

namespace rm {

namespace {

void check_color(const Color& c, const std::string& id, const char* name) {
    if (!is_finite(c) || min_component(c) < 0.f)
        throw std::invalid_argument("emitter '" + id + "': " + name + " must be finite and non-negative");
}

class AreaEmitter final : public Emitter {
public:
    AreaEmitter(const EmitterDesc& d, const Shape* shape) : shape_(shape), radiance_(d.radiance) {
        check_color(radiance_, d.id, "radiance");
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
        ds.radiance = radiance_;
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
        return dot(it.sh.n, w) > 0.f ? radiance_ : Color(0.f);
    }
    // Position by area, direction cosine-weighted about the emitting side's
    // normal: weight = Le cos / (pdf_a cos / pi) = Le pi / pdf_a (PBR4 12.5.1).
    EmissionSample sample_emission(Vec2 u_pos, float u_extra, Vec2 u_dir, const Vec3&, float) const override {
        EmissionSample es;
        PositionSample ps = shape_->sample_position(u_pos, u_extra);
        if (!(ps.pdf_a > 0.f)) return es;
        Vec3 local = warp::square_to_cosine_hemisphere(u_dir);
        if (!(local.z > 0.f)) return es;
        es.p = ps.p;
        es.n = ps.n;
        es.eps = ps.eps;
        es.d = Frame(ps.n).to_world(local);
        es.pdf_a = ps.pdf_a;
        es.pdf_w = warp::square_to_cosine_hemisphere_pdf_w(local);
        es.weight = radiance_ * (kPi / ps.pdf_a);
        return es;
    }
    Color emitted_towards(const EmissionSample& es, const Vec3& w) const override {
        float c = dot(es.n, w);
        if (!(c > 0.f) || !(es.pdf_a > 0.f)) return Color(0.f);
        return radiance_ * (c / es.pdf_a);
    }
    float pdf_emission_a(const Vec3&) const override { return 1.f / shape_->area(); }
    float pdf_emission_w(const Vec3& n, const Vec3& w) const override {
        float c = dot(n, w);
        return c > 0.f ? c * kInvPi : 0.f;
    }

private:
    const Shape* shape_;
    Color radiance_;
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
        DirectSample ds;
        Vec3 v = pos_ - ref;
        float d2 = length_sq(v);
        if (!(d2 > 0.f)) return ds;
        ds.dist = std::sqrt(d2);
        ds.d = v / ds.dist;
        ds.p = pos_;
        ds.pdf_w = 1.f;
        ds.is_delta = true;
        ds.radiance = intensity_ / d2;
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

private:
    Color intensity_;
    Vec3 pos_;
};

class SpotEmitter final : public Emitter {
public:
    explicit SpotEmitter(const EmitterDesc& d) : intensity_(d.intensity) {
        check_color(intensity_, d.id, "intensity");
        if (!xf_.set(d.to_world.data())) throw std::invalid_argument("emitter '" + d.id + "': singular to_world");
        if (!(d.cutoff_angle > 0.f && d.cutoff_angle <= 180.f))
            throw std::invalid_argument("emitter '" + d.id + "': cutoff_angle must be in (0, 180] degrees");
        float beam = d.beam_width < 0.f ? 0.75f * d.cutoff_angle : d.beam_width;
        cutoff_ = d.cutoff_angle * kPi / 180.f;
        beam_ = std::min(beam * kPi / 180.f, cutoff_);
        pos_ = xf_.point(Vec3(0.f));
        delta_ = true;
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
    DirectSample sample_direct(const Vec3& ref, Vec2, float) const override {
        DirectSample ds;
        Vec3 v = pos_ - ref;
        float d2 = length_sq(v);
        if (!(d2 > 0.f)) return ds;
        ds.dist = std::sqrt(d2);
        ds.d = v / ds.dist;
        ds.p = pos_;
        ds.pdf_w = 1.f;
        ds.is_delta = true;
        Vec3 local = normalize(xf_.inv_vector(-ds.d));
        ds.radiance = intensity_ * (falloff(local) / d2);
        return ds;
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
        es.weight = intensity_ * (falloff(local) * 2.f * kPi * omc_max);
        return es;
    }
    Color emitted_towards(const EmissionSample&, const Vec3& w) const override {
        return intensity_ * falloff(normalize(xf_.inv_vector(w)));
    }
    float pdf_emission_w(const Vec3&, const Vec3& w) const override {
        Vec3 local = normalize(xf_.inv_vector(w));
        float theta = std::atan2(std::sqrt(local.x * local.x + local.y * local.y), local.z);
        return theta <= cutoff_ ? 1.f / (2.f * kPi * 2.f * sqr(std::sin(0.5f * cutoff_))) : 0.f;
    }

private:
    Color intensity_;
    Transform xf_;
    Vec3 pos_;
    float cutoff_, beam_;
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

private:
    Color radiance_;
};

}  // namespace

std::unique_ptr<Emitter> make_area_emitter(const EmitterDesc& desc, const Shape* shape) {
    auto e = std::make_unique<AreaEmitter>(desc, shape);
    e->id = desc.id;
    return e;
}

std::unique_ptr<Emitter> make_emitter(const EmitterDesc& desc) {
    std::unique_ptr<Emitter> e;
    if (desc.type == "point")
        e = std::make_unique<PointEmitter>(desc);
    else if (desc.type == "spot")
        e = std::make_unique<SpotEmitter>(desc);
    else if (desc.type == "directional")
        e = std::make_unique<DirectionalEmitter>(desc);
    else if (desc.type == "constant")
        e = std::make_unique<ConstantEmitter>(desc);
    else
        throw std::invalid_argument("emitter '" + desc.id + "': unknown type '" + desc.type + "'");
    e->id = desc.id;
    return e;
}

}  // namespace rm
