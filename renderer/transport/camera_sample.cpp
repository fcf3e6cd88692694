#include "transport/camera_sample.h"

namespace rm {

SensorRay sample_camera_ray(const Sensor& sensor, const FilterSampler& filter, int pixel, Sampler& sampler) {
    const int W = sensor.width, H = sensor.height;
    const int x = pixel % W, y = pixel / W;
    // The offsets, each restricted to the crop window's extent about the
    // pixel centre (Mitsuba's sample_border = false; by default the window
    // is the film); pixels outside the window, which some estimators trace
    // anyway, to the film's.
    int x0 = 0, x1 = W, y0 = 0, y1 = H;
    if (sensor.in_crop(x, y)) {
        x0 = sensor.crop_x, x1 = sensor.crop_x + sensor.crop_w;
        y0 = sensor.crop_y, y1 = sensor.crop_y + sensor.crop_h;
    }
    // One 2D draw (the same two numbers of the independent stream as two 1D
    // draws), so that a structured sampler stratifies the pixel's area.
    Vec2 uf = sampler.next_2d();
    float fx = filter.sample(uf.x, float(x0 - x) - 0.5f, float(x1 - x) - 0.5f);
    float fy = filter.sample(uf.y, float(y0 - y) - 0.5f, float(y1 - y) - 0.5f);
    Vec2 film_pos(float(x) + 0.5f + fx, float(y) + 0.5f + fy);
    // The sensor's own numbers (lens, area sensors' point and direction).
    float u1 = sampler.next_1d();
    Vec2 u2 = sampler.next_2d(), u3 = sampler.next_2d();
    return sensor.sample_ray(film_pos, u1, u2, u3);
}

}  // namespace rm
