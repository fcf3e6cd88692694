#include "scene/sensor.h"

#include <stdexcept>

#include "core/warp.h"
#include "scene/shape.h"

namespace rm {

namespace {

class ProjectiveCamera : public Sensor {
public:
    ProjectiveCamera(const SensorDesc& d) {
        if (!xf_.set(d.to_world.data())) throw std::invalid_argument("sensor: to_world is singular");
        width = d.width;
        height = d.height;
        aspect_ = float(width) / float(height);
        near_ = d.near_clip;
        far_ = d.far_clip;
        if (!(near_ > 0.f) || !(far_ > near_))
            throw std::invalid_argument("sensor: need 0 < near_clip < far_clip");
    }

protected:
    // Local coordinates of a film position on the plane z = 1, spanning
    // [-1, 1] horizontally (times tan_x for perspective), +x to the left.
    Vec2 film_to_plane(Vec2 f) const {
        return {1.f - 2.f * f.x / float(width), (1.f - 2.f * f.y / float(height)) / aspect_};
    }
    Transform xf_;
    float aspect_, near_, far_;
};

class PerspectiveCamera final : public ProjectiveCamera {
public:
    explicit PerspectiveCamera(const SensorDesc& d) : ProjectiveCamera(d) {
        if (!(d.fov_x > 0.f && d.fov_x < 180.f)) throw std::invalid_argument("sensor: fov must be in (0, 180) degrees");
        tan_x_ = std::tan(0.5f * d.fov_x * kPi / 180.f);
        origin_ = xf_.point(Vec3(0.f));
    }
    SensorRay sample_ray(Vec2 f, float, Vec2, Vec2) const override {
        Vec2 q = film_to_plane(f);
        Vec3 local = normalize(Vec3(q.x * tan_x_, q.y * tan_x_, 1.f));
        SensorRay sr;
        Vec3 d = normalize(xf_.vector(local));
        // Mitsuba starts the ray on the near plane and ends it on the far plane.
        float inv_z = 1.f / local.z;
        sr.ray.o = origin_;
        sr.ray.d = d;
        sr.ray.tmin = near_ * inv_z;
        sr.ray.tmax = far_ * inv_z;
        return sr;
    }

private:
    float tan_x_;
    Vec3 origin_;
};

class OrthographicCamera final : public ProjectiveCamera {
public:
    explicit OrthographicCamera(const SensorDesc& d) : ProjectiveCamera(d) {
        dir_ = normalize(xf_.vector(Vec3(0, 0, 1)));
    }
    SensorRay sample_ray(Vec2 f, float, Vec2, Vec2) const override {
        Vec2 q = film_to_plane(f);
        SensorRay sr;
        sr.ray.o = xf_.point(Vec3(q.x, q.y, 0.f));
        sr.ray.d = dir_;
        sr.ray.tmin = near_;
        sr.ray.tmax = far_;
        return sr;
    }

private:
    Vec3 dir_;
};

class RadianceMeter final : public Sensor {
public:
    explicit RadianceMeter(const SensorDesc& d) {
        Transform xf;
        if (!xf.set(d.to_world.data())) throw std::invalid_argument("sensor: to_world is singular");
        o_ = xf.point(Vec3(0.f));
        d_ = normalize(xf.vector(Vec3(0, 0, 1)));
        width = height = 1;
    }
    SensorRay sample_ray(Vec2, float, Vec2, Vec2) const override {
        SensorRay sr;
        sr.ray.o = o_;
        sr.ray.d = d_;
        return sr;
    }

private:
    Vec3 o_, d_;
};

// Mitsuba's irradiancemeter: mean irradiance over the shape's front side.
// Position uniform by area, direction cosine-weighted, so the weight is pi
// (E = int L cos dw, and cos / pdf = pi).
class IrradianceMeter final : public Sensor {
public:
    IrradianceMeter(const SensorDesc&, const Shape* shape) : shape_(shape) {
        if (!shape_) throw std::invalid_argument("sensor: irradiancemeter must be attached to a shape");
        width = height = 1;
    }
    SensorRay sample_ray(Vec2, float u1, Vec2 u2, Vec2 u3) const override {
        PositionSample ps = shape_->sample_position(u2, u1);
        Vec3 local = warp::square_to_cosine_hemisphere(u3);
        Frame fr(ps.n);
        SensorRay sr;
        sr.ray.d = fr.to_world(local);
        sr.ray.o = ps.p + ps.n * ps.eps;
        sr.weight = Color(kPi);
        return sr;
    }

private:
    const Shape* shape_;
};

}  // namespace

std::unique_ptr<Sensor> make_sensor(const SensorDesc& d, const Shape* shape) {
    if (d.width < 1 || d.height < 1 || d.width > 16384 || d.height > 16384)
        throw std::invalid_argument("sensor: film size " + std::to_string(d.width) + "x" + std::to_string(d.height) +
                                    " is outside 1..16384");
    if (d.type == "perspective") return std::make_unique<PerspectiveCamera>(d);
    if (d.type == "orthographic") return std::make_unique<OrthographicCamera>(d);
    if (d.type == "radiancemeter") return std::make_unique<RadianceMeter>(d);
    if (d.type == "irradiancemeter") return std::make_unique<IrradianceMeter>(d, shape);
    throw std::invalid_argument("sensor: unknown type '" + d.type + "'");
}

}  // namespace rm
