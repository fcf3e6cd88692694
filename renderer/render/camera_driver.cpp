// The camera driver: camera rays through every pixel, tile by tile, on the
// pass loop. Results are identical for a given seed whatever the thread
// count: every (pixel, sample) has its own random stream (the independent
// PCG stream, or the render's structured sampler, a function of seed, pixel,
// sample and dimension: core/sampler.h), each pixel's samples are
// accumulated in order by one thread, and a pass joins the film only when
// complete.
#include <algorithm>
#include <atomic>
#include <optional>
#include <stdexcept>
#include <string>

#include "render/memory.h"
#include "render/pass_loop.h"
#include "transport/camera_sample.h"

namespace rm {

namespace {

constexpr int kTile = 16;
std::atomic<bool> g_camera_packets{true};

class CameraStep final : public PassStep {
public:
    CameraStep(const Scene& scene, const Integrator& integrator, bool effect_variance, const SamplerPlan& plan)
        : scene_(scene),
          integrator_(integrator),
          W_(scene.sensor->width),
          H_(scene.sensor->height),
          cx_(scene.sensor->crop_x),
          cy_(scene.sensor->crop_y),
          cw_(scene.sensor->crop_w),
          ch_(scene.sensor->crop_h),
          filter_(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev),
          film_(W_, H_, effect_variance),
          pass_film_(W_, H_, effect_variance),
          tiles_x_((cw_ + kTile - 1) / kTile),
          tiles_y_((ch_ + kTile - 1) / kTile),
          plan_(plan),
          packets_(integrator.takes_camera_hits() && g_camera_packets.load()) {}

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
        if (packets_) {
            if (render_rows_in_packets(loop, x0, y0, x1, y1, s0, s1, stats))
                loop.add_done(uint64_t(s1 - s0) * uint64_t((x1 - x0) * (y1 - y0)));
            return;
        }
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

    // The tile's camera rays sample by sample, row by row, kPacket
    // neighbouring pixels traced as one packet (Scene::intersect_packet),
    // each path then going on alone from its hit. Every pixel still
    // receives its samples in order from its own streams, so the bytes are
    // those of render_sample. False when cancelled.
    bool render_rows_in_packets(PassLoop& loop, int x0, int y0, int x1, int y1, int s0, int s1, ThreadStats& stats) {
        constexpr int kP = Scene::kPacket;
        std::optional<PixelSampleSource> sources[kP];
        std::optional<Sampler> samplers[kP];
        SensorRay rays[kP];
        Ray packet[kP];
        Interaction hits[kP];
        bool hit[kP];
        for (int s = s0; s < s1; ++s)
            for (int y = y0; y < y1; ++y) {
                if (loop.cancelled()) return false;
                for (int xa = x0; xa < x1; xa += kP) {
                    const int n = std::min(kP, x1 - xa);
                    // 1. Each pixel's stream and its filter-sampled camera ray.
                    for (int i = 0; i < n; ++i) {
                        const int pixel = y * W_ + xa + i;
                        if (plan_.independent()) {
                            samplers[i].emplace(loop.seed(), uint64_t(pixel), uint64_t(s));
                        } else {
                            sources[i].emplace(plan_, uint64_t(pixel), uint64_t(s));
                            samplers[i].emplace(&*sources[i]);
                        }
                        rays[i] = sample_camera_ray(*scene_.sensor, filter_, pixel, *samplers[i]);
                        packet[i] = rays[i].ray;
                    }
                    // 2. Their closest hits in one packet.
                    scene_.intersect_packet(packet, n, hits, hit);
                    // 3. Each path from its hit, into the pass's film.
                    for (int i = 0; i < n; ++i) {
                        EffectRadiance er;
                        ++stats.paths;
                        integrator_.sample_from_hit(scene_, *samplers[i], packet[i], hit[i] ? &hits[i] : nullptr, er,
                                                    stats);
                        add_sample(y * W_ + xa + i, rays[i].weight, er, stats);
                    }
                }
            }
        return true;
    }

    void render_sample(Sampler& sampler, int pixel, ThreadStats& stats) {
        if (__builtin_expect(ray_log_attached(), 0)) ray_log_begin_sample();
        SensorRay sr = sample_camera_ray(*scene_.sensor, filter_, pixel, sampler);
        // 2. The estimator's radiance along it, by effect, times the ray's weight.
        EffectRadiance er;
        ++stats.paths;
        integrator_.sample(scene_, sampler, sr.ray, er, stats);
        add_sample(pixel, sr.weight, er, stats);
    }

    // A sample's radiance times its camera ray's weight into the pass's film.
    void add_sample(int pixel, const Color& weight, EffectRadiance& er, ThreadStats& stats) {
        Color total(0.f);
        for (int k = 0; k < kNumEffects; ++k) {
            er.by_effect[k] *= weight;
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
    const bool packets_;  // camera rays in packets (render_rows_in_packets)
};

}  // namespace

void set_camera_packets(bool on) { g_camera_packets = on; }

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
