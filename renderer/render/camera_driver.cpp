// The camera driver: camera rays through every pixel, tile by tile, on the
// pass loop. Results are identical for a given seed whatever the thread
// count: every (pixel, sample) has its own random stream (the independent
// PCG stream, or the render's structured sampler, a function of seed, pixel,
// sample and dimension: core/sampler.h), each pixel's samples are
// accumulated in order by one thread, and a pass joins the film only when
// complete.
#include <algorithm>
#include <stdexcept>
#include <string>

#include "render/memory.h"
#include "render/pass_loop.h"
#include "transport/camera_sample.h"

namespace rm {

namespace {

constexpr int kTile = 16;

class CameraStep final : public PassStep {
public:
    CameraStep(const Scene& scene, const Integrator& integrator, bool effect_variance, const SamplerPlan& plan)
        : scene_(scene),
          integrator_(integrator),
          W_(scene.sensor->width),
          H_(scene.sensor->height),
          filter_(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev),
          cx_(scene.sensor->crop_x),
          cy_(scene.sensor->crop_y),
          cw_(scene.sensor->crop_w),
          ch_(scene.sensor->crop_h),
          film_(W_, H_, effect_variance),
          pass_film_(W_, H_, effect_variance),
          tiles_x_((cw_ + kTile - 1) / kTile),
          tiles_y_((ch_ + kTile - 1) / kTile),
          plan_(plan) {}

    int pass(PassLoop& loop, int s0, int s1) override {
        // 1. Tiles over threads, into the film of the pass in flight.
        auto tile = [&](size_t i, int t) { render_tile(loop, int(i), s0, s1, loop.stats(t)); };
        if (!loop.parallel_for(size_t(tiles_x_) * size_t(tiles_y_), tile)) return s0;  // the unfinished pass is dropped
        // 2. The complete pass joins the finished ones.
        film_.merge_and_clear(pass_film_);
        return s1;
    }

    void develop(int spp, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const override {
        film_.develop(spp, image, variance, effects);
    }

    void develop_effect_variance(int spp, std::vector<std::vector<float>>& variance) const override {
        film_.develop_effect_variance(spp, variance);
    }

private:
    void render_tile(PassLoop& loop, int tile, int s0, int s1, ThreadStats& stats) {
        // Tiles cover the crop window (by default the film); a pixel keeps
        // its film index, and with it its random streams.
        int x0 = cx_ + (tile % tiles_x_) * kTile, y0 = cy_ + (tile / tiles_x_) * kTile;
        int x1 = std::min(x0 + kTile, cx_ + cw_), y1 = std::min(y0 + kTile, cy_ + ch_);
        for (int y = y0; y < y1; ++y)
            for (int x = x0; x < x1; ++x) {
                if (loop.cancelled()) return;
                int pixel = y * W_ + x;
                for (int s = s0; s < s1; ++s) {
                    // 1. The sample's own stream and its filter-sampled camera ray.
                    if (plan_.independent()) {
                        Sampler sampler(loop.seed(), uint64_t(pixel), uint64_t(s));
                        render_sample(sampler, pixel, stats);
                    } else {
                        PixelSampleSource source(plan_, uint64_t(pixel), uint64_t(s));
                        Sampler sampler(&source);
                        render_sample(sampler, pixel, stats);
                    }
                }
            }
        loop.add_done(uint64_t(s1 - s0) * uint64_t((x1 - x0) * (y1 - y0)));
    }

    void render_sample(Sampler& sampler, int pixel, ThreadStats& stats) {
        SensorRay sr = sample_camera_ray(*scene_.sensor, filter_, pixel, sampler);
        // 2. The estimator's radiance along it, by effect, times the ray's weight.
        EffectRadiance er;
        ++stats.paths;
        integrator_.sample(scene_, sampler, sr.ray, er, stats);
        Color total(0.f);
        for (int k = 0; k < kNumEffects; ++k) {
            er.by_effect[k] *= sr.weight;
            total += er.by_effect[k];
        }
        // 3. Into the pass's film, unless NaN or Inf (counted, dropped).
        if (!keep_finite(stats, total)) er = EffectRadiance();
        pass_film_.add(pixel, er);
    }

    const Scene& scene_;
    const Integrator& integrator_;
    const int W_, H_;
    const int cx_, cy_, cw_, ch_;  // the crop window
    FilterSampler filter_;
    Film film_;       // finished passes
    Film pass_film_;  // the pass in flight; merged only when complete
    const int tiles_x_, tiles_y_;
    const SamplerPlan& plan_;
};

}  // namespace

RenderOutput render_camera_paths(PassLoop& loop, const Integrator& integrator) {
    const Scene& scene = loop.scene();
    int W = scene.sensor->width, H = scene.sensor->height;
    // Said up front rather than failing inside an allocation (memory.h).
    const bool effvar = loop.options().effect_variance;
    check_memory(integrator.type, W, H, {camera_film_memory(W, H, effvar), output_memory(loop.options(), W, H)});
    const RenderOptions& opts = loop.options();
    SamplerPlan plan(opts.sampler, opts.spp, W, H, opts.seed);
    CameraStep step(scene, integrator, effvar, plan);
    loop.set_pixels(uint64_t(scene.sensor->crop_w) * uint64_t(scene.sensor->crop_h));  // the window's, for progress
    RenderOutput out = loop.run(step);
    out.sampler = plan.name();
    return out;
}

RenderOutput render_camera_paths(const Scene& scene, const Integrator& integrator, const RenderOptions& opts,
                                 const PollFn& poll) {
    PassLoop loop(scene, opts, poll);
    return render_camera_paths(loop, integrator);
}

}  // namespace rm
