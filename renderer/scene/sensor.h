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
};

class Sensor {
public:
    virtual ~Sensor() = default;
    int width = 1, height = 1;
    // film: continuous film position in [0, width] x [0, height]; u1, u2, u3 for
    // sensors that integrate over area or direction.
    virtual SensorRay sample_ray(Vec2 film, float u1, Vec2 u2, Vec2 u3) const = 0;
};

// shape: the shape an irradiancemeter is attached to (else ignored).
std::unique_ptr<Sensor> make_sensor(const SensorDesc& desc, const Shape* shape);

}  // namespace rm
