#include "transport/camera_sample.h"

namespace rm {

SensorRay sample_camera_ray(const Sensor& sensor, const FilterSampler& filter, int pixel, Sampler& sampler) {
    const int W = sensor.width, H = sensor.height;
    const int x = pixel % W, y = pixel / W;
    // The offsets, each restricted to the film's extent about the pixel centre.
    float fx = filter.sample(sampler.next_1d(), -float(x) - 0.5f, float(W - x) - 0.5f);
    float fy = filter.sample(sampler.next_1d(), -float(y) - 0.5f, float(H - y) - 0.5f);
    Vec2 film_pos(float(x) + 0.5f + fx, float(y) + 0.5f + fy);
    // The sensor's own numbers (lens, area sensors' point and direction).
    float u1 = sampler.next_1d();
    Vec2 u2 = sampler.next_2d(), u3 = sampler.next_2d();
    return sensor.sample_ray(film_pos, u1, u2, u3);
}

}  // namespace rm
