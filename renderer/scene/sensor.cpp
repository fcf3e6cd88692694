#include "scene/sensor.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/warp.h"
#include "scene/shape.h"

namespace rm {

namespace {

class ProjectiveCamera : public Sensor {
public:
    ProjectiveCamera(const SensorDesc& d) {
        if (!xf_.set(d.to_world.data())) throw std::invalid_argument("sensor: to_world is singular");
        // Directions are normalised in float32, whose squared lengths under-
        // or overflow beyond about 1e+-19: refuse axis scales outside 1e+-18.
        for (int c = 0; c < 3; ++c) {
            const double* m = d.to_world.data();
            double len = std::sqrt(m[c] * m[c] + m[4 + c] * m[4 + c] + m[8 + c] * m[8 + c]);
            if (!(len >= 1e-18 && len <= 1e18)) {
                char buf[160];
                std::snprintf(buf, sizeof buf,
                              "sensor: to_world scales axis %c by %g, outside what float32 ray directions "
                              "represent (1e-18 to 1e18)",
                              char('x' + c), len);
                throw std::invalid_argument(buf);
            }
        }
        width = d.width;
        height = d.height;
        aspect_ = float(width) / float(height);
        near_ = d.near_clip;
        far_ = d.far_clip;
        if (!(near_ > 0.f) || !(far_ > near_)) throw std::invalid_argument("sensor: need 0 < near_clip < far_clip");
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
    bool has_importance() const override { return true; }
    ImportanceSample sample_direction(const Vec3& ref) const override {
        ImportanceSample is;
        Vec3 v = origin_ - ref;
        float dist = length(v);
        if (!(dist > 0.f)) return is;
        // The ray from the pinhole through ref, in camera space; its film
        // position inverts film_to_plane.
        Vec3 local = normalize(xf_.inv_vector(-v));
        if (!film_of(local, is.film)) return is;
        // sample_ray's clip range: t in [near, far] / cos theta.
        if (dist * local.z < near_ || dist * local.z > far_) return is;
        is.valid = true;
        is.p = origin_;
        is.d = v / dist;
        is.dist = dist;
        is.weight = importance_w(local.z) / (dist * dist);
        is.clip = near_ / local.z;
        return is;
    }
    ImportanceSample eval_direction(const Vec3& w, Ray* ray) const override {
        ImportanceSample is;
        Vec3 local = normalize(xf_.inv_vector(w));
        if (!film_of(local, is.film)) return is;
        is.valid = true;
        is.p = origin_;
        is.d = -w;
        is.dist = kInf;
        is.weight = importance_w(local.z);
        if (ray) {
            ray->o = origin_;
            ray->d = w;
            ray->tmin = near_ / local.z;
            ray->tmax = far_ / local.z;
        }
        return is;
    }

private:
    // Film position of the camera-space unit direction `local`; false outside the film.
    bool film_of(const Vec3& local, Vec2& film) const {
        if (!(local.z > 0.f)) return false;
        float qx = local.x / (local.z * tan_x_), qy = local.y / (local.z * tan_x_);
        film = Vec2(0.5f * float(width) * (1.f - qx), 0.5f * float(height) * (1.f - qy * aspect_));
        return film.x >= 0.f && film.x <= float(width) && film.y >= 0.f && film.y <= float(height);
    }
    // Importance per steradian in pixel units: a film area dA on the plane
    // z = 1 subtends dw = dA cos^3 theta, and one pixel there has area
    // A_pix = (2 tan_x)(2 tan_x / aspect) / (W H) (pbrt-v4 PerspectiveCamera::We).
    float importance_w(float cos_t) const {
        float a_pix = 4.f * tan_x_ * tan_x_ / aspect_ / (float(width) * float(height));
        return 1.f / (a_pix * cos_t * cos_t * cos_t);
    }
    float tan_x_;
    Vec3 origin_;
};

class OrthographicCamera final : public ProjectiveCamera {
public:
    explicit OrthographicCamera(const SensorDesc& d) : ProjectiveCamera(d) {
        dir_ = normalize(xf_.vector(Vec3(0, 0, 1)));
        z_scale_ = length(xf_.vector(Vec3(0, 0, 1)));
        // Area of one pixel across the beam (perpendicular to dir_), world units.
        float a_plane = std::fabs(dot(cross(xf_.vector(Vec3(1, 0, 0)), xf_.vector(Vec3(0, 1, 0))), dir_));
        a_pix_ = a_plane * 4.f / aspect_ / (float(width) * float(height));
    }
    bool has_importance() const override { return true; }
    // The ray through ref is the one parallel to dir_: its film point is ref
    // projected along dir_; the importance per unit area across the beam is
    // 1 / a_pix_ (a delta in direction, so only points connect).
    ImportanceSample sample_direction(const Vec3& ref) const override {
        ImportanceSample is;
        Vec3 l = xf_.inv_point(ref);
        Vec2 f(0.5f * float(width) * (1.f - l.x), 0.5f * float(height) * (1.f - l.y * aspect_));
        if (!(f.x >= 0.f && f.x <= float(width) && f.y >= 0.f && f.y <= float(height))) return is;
        float t = l.z * z_scale_;
        if (!(t >= near_ && t <= far_) || !(a_pix_ > 0.f)) return is;
        is.valid = true;
        is.film = f;
        is.p = xf_.point(Vec3(l.x, l.y, 0.f));
        is.d = -dir_;
        is.dist = t;
        is.weight = 1.f / a_pix_;
        is.clip = near_;
        return is;
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
    float z_scale_, a_pix_;
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
//
// As a target of light paths: the measurement (1 / A) int_A int L cos dw dA
// has importance W_e = 1 / A per unit area and projected solid angle. A
// point x drawn on the shape with density p_A(x) and reached from ref along
// d (distance r) gives ref the importance W_e cos_x / (p_A r^2) per unit of
// its area (the cosine at ref is the caller's): cos_x / r^2 where the shape
// is sampled uniformly by area (Veach 1997, eq. 8.7 with the geometry term
// split between its two ends). Only the front side measures.
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
        sr.n = ps.n;
        return sr;
    }
    bool has_importance() const override { return true; }
    bool area_sensor() const override { return true; }
    ImportanceSample sample_direction(const Vec3& ref, Vec2 u, float u_extra) const override {
        ImportanceSample is;
        PositionSample ps = shape_->sample_position(u, u_extra);
        Vec3 v = ps.p - ref;
        float d2 = length_sq(v);
        if (!(d2 > 0.f) || !(ps.pdf_a > 0.f)) return is;
        float dist = std::sqrt(d2);
        Vec3 d = v / dist;
        float cos_x = -dot(ps.n, d);  // the front side faces ref
        if (!(cos_x > 0.f)) return is;
        is.valid = true;
        is.film = Vec2(0.5f, 0.5f);
        // The sensor point where sample_ray's rays start (ps.eps off the
        // shape along its normal), so that bdpt's camera vertex is the same
        // point in every strategy (its MIS densities are measured from it).
        is.p = ps.p + ps.n * ps.eps;
        is.d = d;
        is.dist = dist;
        is.n = ps.n;
        is.weight = cos_x / (ps.pdf_a * shape_->area() * d2);  // W_e = 1 / A
        // Connections end this far short of that point (clear of the shape itself).
        is.clip = std::min(ps.eps * 4.f, 0.5f * dist);
        return is;
    }
    float pdf_ray_direction(const Vec3& n0, const Vec3& w) const override {
        return std::max(0.f, dot(n0, w)) * kInvPi;  // square_to_cosine_hemisphere
    }

private:
    const Shape* shape_;
};

}  // namespace

std::unique_ptr<Sensor> make_sensor(const SensorDesc& d, const Shape* shape) {
    if (d.width < 1 || d.height < 1 || d.width > 16384 || d.height > 16384)
        throw std::invalid_argument("sensor: film size " + std::to_string(d.width) + "x" + std::to_string(d.height) +
                                    " is outside 1..16384");
    std::unique_ptr<Sensor> s;
    if (d.type == "perspective")
        s = std::make_unique<PerspectiveCamera>(d);
    else if (d.type == "orthographic")
        s = std::make_unique<OrthographicCamera>(d);
    else if (d.type == "radiancemeter")
        s = std::make_unique<RadianceMeter>(d);
    else if (d.type == "irradiancemeter")
        s = std::make_unique<IrradianceMeter>(d, shape);
    else
        throw std::invalid_argument("sensor: unknown type '" + d.type + "'");
    s->crop_w = d.crop_width > 0 ? d.crop_width : s->width;
    s->crop_h = d.crop_height > 0 ? d.crop_height : s->height;
    s->crop_x = d.crop_x;
    s->crop_y = d.crop_y;
    if (s->crop_x < 0 || s->crop_y < 0 || s->crop_w > s->width - s->crop_x || s->crop_h > s->height - s->crop_y)
        throw std::invalid_argument("sensor: crop window " + std::to_string(s->crop_w) + "x" +
                                    std::to_string(s->crop_h) + " at (" + std::to_string(s->crop_x) + ", " +
                                    std::to_string(s->crop_y) + ") exceeds the " + std::to_string(s->width) + "x" +
                                    std::to_string(s->height) + " film");
    return s;
}

}  // namespace rm
