// The camera end of every camera path: a pixel's camera ray, its film
// position drawn by filter importance sampling (Ernst et al. 2006, "Filter
// Importance Sampling"), shared by the camera driver, sppm's visible points
// and bdpt's camera subpaths.
#pragma once
#include "core/rng.h"
#include "film/film.h"
#include "scene/sensor.h"

namespace rm {

// The camera ray of one sample of `pixel` (y * width + x). The film
// position is the pixel centre plus an offset per axis drawn with density
// proportional to the filter, kept inside the film (FilterSampler), so every
// sample belongs to exactly one pixel; then the sensor's ray through it.
// Draws, in order: the two offsets, then 1 + 2 + 2 numbers for sample_ray.
SensorRay sample_camera_ray(const Sensor& sensor, const FilterSampler& filter, int pixel, Sampler& sampler);

}  // namespace rm
