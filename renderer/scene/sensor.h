// Sensors: perspective, orthographic, radiancemeter, irradiancemeter. Camera
// conventions follow Mitsuba 3 (local +z looks forward, +x is left, +y up;
// pixel (0, 0) is the top-left corner of the film).
#pragma once
#include <memory>

#include "core/math.h"
#include "core/spectrum.h"
#include "scene/desc.h"
#include "scene/records.h"

namespace rm {

class Shape;

struct SensorRay {
    Ray ray;
    Color weight{1.f};
    Vec3 n{0.f};  // area sensors (irradiancemeter): the normal at the ray's origin; zero for a pinhole
};

// The sensor end of a light path (the t = 1 strategy of Veach 1997, sec.
// 10.2; pbrt-v4's Camera::SampleWi). `weight` is the importance arriving at
// the reference point per unit of its area and per unit of film area
// measured in pixels, without the reference point's cosine: a light subpath
// of flux-weight beta ending at x with BSDF f splats
// beta f |cos_x| weight at `film`, and the mean over M light paths of those
// splats (filtered) is the pixel estimate of a camera-side estimator (see
// ptracer.cpp). Pinhole: W = 1 / (A_pix cos^3 theta dist^2), A_pix the area
// of one pixel on the plane at distance 1 (pbrt-v4 PerspectiveCamera::We
// times the conversion of dw to film area).
struct ImportanceSample {
    bool valid = false;
    Vec2 film;           // continuous film position, [0, width] x [0, height]
    Vec3 p;              // the sensor point reached (pinhole, or the orthographic film-plane point)
    Vec3 d;              // unit direction from the reference point towards p
    float dist = 0.f;    // distance from the reference point to p
    float weight = 0.f;  // importance as described above; per steradian for eval_direction
    float clip = 0.f;    // distance from p towards the reference point at which camera rays start (near clip)
    Vec3 n{0.f};         // area sensors: the normal at p; zero for a pinhole
};

class Sensor {
public:
    virtual ~Sensor() = default;
    int width = 1, height = 1;
    // The crop window (desc.h): pixels [crop_x, crop_x + crop_w) x [crop_y,
    // crop_y + crop_h) are rendered; the full film above fixes the geometry.
    int crop_x = 0, crop_y = 0, crop_w = 1, crop_h = 1;
    bool in_crop(int x, int y) const {
        return x >= crop_x && x < crop_x + crop_w && y >= crop_y && y < crop_y + crop_h;
    }
    // film: continuous film position in [0, width] x [0, height]; u1, u2, u3 for
    // sensors that integrate over area or direction.
    virtual SensorRay sample_ray(Vec2 film, float u1, Vec2 u2, Vec2 u3) const = 0;
    // Light tracing support: sensors whose importance a point can connect to.
    virtual bool has_importance() const { return false; }
    // Connects the point `ref` to the sensor; invalid when it is outside the
    // field of view or the clip range.
    virtual ImportanceSample sample_direction(const Vec3& ref) const { return {}; }
    // Sensors with an area (irradiancemeter): the point on the sensor is
    // sampled too, from `u` and `u_extra`; then `weight` above divides by its area density
    // (the importance of a point of an area sensor, W_e, is per unit area
    // and projected solid angle; Veach 1997, sec. 8.2 and 10.2).
    virtual bool area_sensor() const { return false; }
    virtual ImportanceSample sample_direction(const Vec3& ref, Vec2 u, float u_extra) const {
        return sample_direction(ref);
    }
    // Area sensors: the density per steradian with which sample_ray leaves
    // a point of normal n0 in direction w (for bidirectional MIS).
    virtual float pdf_ray_direction(const Vec3& n0, const Vec3& w) const { return 0.f; }
    // Importance per steradian along the camera ray leaving in direction w
    // (emitters at infinity seen directly); `ray` gets that camera ray with
    // its clip range. Invalid for sensors whose directions are a delta.
    virtual ImportanceSample eval_direction(const Vec3& w, Ray* ray) const { return {}; }
};

// shape: the shape an irradiancemeter is attached to (else ignored).
std::unique_ptr<Sensor> make_sensor(const SensorDesc& desc, const Shape* shape);

}  // namespace rm
