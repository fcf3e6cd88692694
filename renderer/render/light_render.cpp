// The render driver of light-tracing estimators (ptracer): light paths
// instead of camera tiles, their splats filtered onto the film.
//
// Which light paths: a render of `spp` traces M = spp * W * H of them, light
// path g = s * W * H + j (s < spp, j < W * H) drawing on Sampler(seed, j, s)
// (or sample s of pixel j of the render's structured sampler, core/sampler.h),
// so every path's random numbers are fixed by the seed alone.
//
// Determinism whatever the thread count: the paths of a pass are cut into
// work items of kItemPaths consecutive paths (not by thread); threads trace
// items in any order, each into the item's own list of splats, and the lists
// are added to the film in item order (the film's rows are shared out among
// threads, each adding every splat that touches its rows, in item order), so
// every pixel sums the same numbers in the same order.
//
// Filtering: a splat at film position (x, y) adds to every pixel (px, py)
// whose filter footprint covers it, with weight f(x - cx) f(y - cy) / (N_x
// N_y), (cx, cy) the pixel centre and N the filter's integral over the
// footprint's part inside the film: the expectation is then exactly the
// estimate of the camera-side estimators, whose filter importance sampling
// draws film positions with density f / N (film.h), borders included.
//
// Variance: batch means (e.g. Glynn & Whitt 1991; Law & Kelton, "Simulation
// Modeling and Analysis", sec. 9.5). Path g = s W H + j belongs to batch
// (j + s) mod kBatches (batch_of), so that the camera samples of one pixel,
// which bdpt traces along with light path g = s W H + j, spread over all
// batches (with g mod kBatches and W H a multiple of 32 they all fell into
// one batch and the batch means overestimated their variance ~100-fold);
// with I_b the estimate from batch b's n_b paths alone and I the estimate from
// all M, var = sum_b n_b (I_b - I)^2 / ((B - 1) M) is an unbiased estimate of
// Var(I) (the one-way ANOVA identity E[sum_b n_b (I_b - I)^2] = (B - 1)
// sigma^2 for independent paths of variance sigma^2, whatever the n_b). It
// has B - 1 = 31 degrees of freedom.
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "render/memory.h"
#include "render/pass_loop.h"

namespace rm {

namespace {

constexpr int kBatches = 32;

inline int batch_of(uint64_t g, uint64_t pixels) { return int((g % pixels + g / pixels) % kBatches); }

// Number of j in [0, n) with j mod kBatches == k.
inline uint64_t count_residue(uint64_t n, int k) { return n / kBatches + (uint64_t(k) < n % kBatches ? 1 : 0); }

// n_b: the number of the first `paths` light paths in each batch (batch_of).
void batch_sizes(uint64_t paths, uint64_t pixels, double* n_b) {
    uint64_t full = paths / pixels, rem = paths % pixels;
    for (int b = 0; b < kBatches; ++b) {
        double n = 0;
        for (int r = 0; r < kBatches; ++r) {  // sample indices s < full with s mod B == r
            uint64_t c_r = count_residue(full, r);
            if (c_r) n += double(c_r) * double(count_residue(pixels, ((b - r) % kBatches + kBatches) % kBatches));
        }
        // the partial sample index `full`: pixels j < rem
        n +=
            double(count_residue(rem, int(((int64_t(b) - int64_t(full % kBatches)) % kBatches + kBatches) % kBatches)));
        n_b[b] = n;
    }
}
constexpr uint64_t kItemPaths = 1024;  // light paths per work item
constexpr uint64_t kChunkItems = 256;  // items traced before their splats join the film (bounds memory)

struct ItemSplat {
    Splat s;
    int batch;
};

class SplatFilm {
public:
    // The crop window (sensor.h) bounds the film positions splatted, as it
    // bounds the camera side's samples (camera_sample.cpp).
    SplatFilm(const Sensor& s, const FilterSampler& f, int n_strategies)
        : w_(s.width),
          h_(s.height),
          n_strat_(n_strategies),
          filter_(f),
          cx0_(s.crop_x),
          cy0_(s.crop_y),
          cx1_(s.crop_x + s.crop_w),
          cy1_(s.crop_y + s.crop_h) {
        const int w = w_, h = h_;
        size_t n = size_t(w) * size_t(h);
        effects_.assign(n * kNumEffects * 3, 0.0);
        strat_.assign(n * size_t(n_strat_) * 6, 0.0);
        batches_.assign(n * kBatches * 3, 0.0);
        norm_x_ = splat_norms(filter_, w, cx0_, cx1_);
        norm_y_ = splat_norms(filter_, h, cy0_, cy1_);
    }

    // Adds the items' splats, in item order, to the rows [y0, y1).
    void merge(const std::vector<std::vector<ItemSplat>>& items, size_t n_items, int y0, int y1) {
        for (size_t i = 0; i < n_items; ++i)
            for (const ItemSplat& is : items[i]) {
                if (is.s.pixel >= 0) {  // a camera sample: its own pixel only (integrator.h)
                    int py = is.s.pixel / w_;
                    if (py < y0 || py >= y1) continue;
                    size_t p = size_t(is.s.pixel);
                    double* e = &effects_[(p * kNumEffects + is.s.effect) * 3];
                    double* b = &batches_[(p * kBatches + is.batch) * 3];
                    for (int c = 0; c < 3; ++c) {
                        e[c] += double(is.s.value[c]);
                        b[c] += double(is.s.value[c]);
                    }
                    add_strategy(p, is.s, 1.0);
                    continue;
                }
                float x = is.s.film.x, y = is.s.film.y;
                if (x < float(cx0_) || x > float(cx1_) || y < float(cy0_) || y > float(cy1_)) continue;
                for_each_splat_pixel(filter_, norm_x_, norm_y_, w_, y0, y1, x, y, [&](size_t p, double wgt) {
                    double* e = &effects_[(p * kNumEffects + is.s.effect) * 3];
                    double* b = &batches_[(p * kBatches + is.batch) * 3];
                    for (int c = 0; c < 3; ++c) {
                        double v = wgt * double(is.s.value[c]);
                        e[c] += v;
                        b[c] += v;
                    }
                    add_strategy(p, is.s, wgt);
                });
            }
    }

    // The splat's strategy images: weighted, and unweighted (value / weight).
    void add_strategy(size_t p, const Splat& s, double wgt) {
        if (s.strategy < 0 || s.strategy >= n_strat_) return;
        double* d = &strat_[(p * size_t(n_strat_) + size_t(s.strategy)) * 6];
        double inv_w = s.weight > 0.f ? 1.0 / double(s.weight) : 0.0;
        for (int c = 0; c < 3; ++c) {
            d[c] += wgt * double(s.value[c]);
            d[3 + c] += wgt * double(s.value[c]) * inv_w;
        }
    }

    void develop_strategies(uint64_t paths, std::vector<std::vector<float>>& weighted,
                            std::vector<std::vector<float>>& unweighted) const {
        size_t n = size_t(w_) * size_t(h_);
        weighted.assign(size_t(n_strat_), std::vector<float>(3 * n, 0.f));
        unweighted.assign(size_t(n_strat_), std::vector<float>(3 * n, 0.f));
        if (paths == 0) return;
        double inv_m = 1.0 / double(paths);
        for (size_t p = 0; p < n; ++p)
            for (int k = 0; k < n_strat_; ++k)
                for (int c = 0; c < 3; ++c) {
                    const double* d = &strat_[(p * size_t(n_strat_) + size_t(k)) * 6];
                    weighted[k][3 * p + c] = float(d[c] * inv_m);
                    unweighted[k][3 * p + c] = float(d[3 + c] * inv_m);
                }
    }

    // Estimates from the first `paths` light paths (see the top of the file).
    void develop(uint64_t paths, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const {
        size_t n = size_t(w_) * size_t(h_);
        image.assign(3 * n, 0.f);
        variance.assign(3 * n, std::numeric_limits<float>::quiet_NaN());
        if (effects) effects->assign(kNumEffects, std::vector<float>(3 * n, 0.f));
        if (paths == 0) return;
        double inv_m = 1.0 / double(paths);
        double n_b[kBatches];
        int b_eff = 0;
        batch_sizes(paths, uint64_t(w_) * uint64_t(h_), n_b);
        for (int b = 0; b < kBatches; ++b) {
            if (n_b[b] > 0) ++b_eff;
        }
        for (size_t p = 0; p < n; ++p)
            for (int c = 0; c < 3; ++c) {
                double total = 0;
                for (int k = 0; k < kNumEffects; ++k) {
                    double ek = effects_[(p * kNumEffects + k) * 3 + c] * inv_m;
                    total += ek;
                    if (effects) (*effects)[k][3 * p + c] = float(ek);
                }
                image[3 * p + c] = float(total);
                if (b_eff < 2) continue;  // too few batches: NaN, never a fake 0
                double sum = 0;
                for (int b = 0; b < kBatches; ++b) sum += batches_[(p * kBatches + b) * 3 + c];
                double mean = sum * inv_m, ss = 0;
                for (int b = 0; b < kBatches; ++b)
                    if (n_b[b] > 0) {
                        double d = batches_[(p * kBatches + b) * 3 + c] / n_b[b] - mean;
                        ss += n_b[b] * d * d;
                    }
                variance[3 * p + c] = float(ss / ((b_eff - 1) * double(paths)));
            }
    }

private:
    int w_, h_, n_strat_;
    const FilterSampler& filter_;
    int cx0_, cy0_, cx1_, cy1_;    // the crop window
    std::vector<double> strat_;    // [pixel][strategy][weighted rgb, unweighted rgb] sums
    std::vector<double> effects_;  // [pixel][effect][channel] sums
    std::vector<double> batches_;  // [pixel][batch][channel] sums
    std::vector<double> norm_x_, norm_y_;
};

// The light driver's pass: the light paths of samples [s0, s1) per pixel,
// in chunks of up to kChunkItems work items (bounds the splats in memory).
class LightStep final : public PassStep {
public:
    LightStep(const Scene& scene, const Integrator& integrator, const FilterSampler& filter, int n_strat, int threads,
              const SamplerPlan& plan)
        : scene_(scene),
          integrator_(integrator),
          pixels_(uint64_t(scene.sensor->width) * uint64_t(scene.sensor->height)),
          n_strat_(n_strat),
          film_(*scene.sensor, filter, n_strat),
          stripes_(std::min(scene.sensor->height, threads * 4)),
          items_(kChunkItems),
          plan_(plan) {}

    int pass(PassLoop& loop, int s0, int s1) override {
        const uint64_t g_end = uint64_t(s1) * pixels_;
        while (paths_done_ < g_end) {
            // 1. Trace a chunk's items over threads, each into its own splat list.
            const uint64_t g0 = paths_done_, chunk_paths = std::min(g_end - g0, kChunkItems * kItemPaths);
            size_t n_items = size_t((chunk_paths + kItemPaths - 1) / kItemPaths);
            auto trace_item = [&](size_t i, int t) {
                uint64_t a = g0 + i * kItemPaths, b = std::min(g0 + chunk_paths, a + kItemPaths);
                trace_paths(loop, a, b, items_[i], loop.stats(t));
            };
            // A cancel drops the unfinished chunk; finished chunks stand, and
            // the estimate uses every light path they traced.
            if (!loop.parallel_for(n_items, trace_item)) return int(paths_done_ / pixels_);
            // 2. Add the splats to the film in item order, rows shared out among threads.
            const int H = scene_.sensor->height;
            auto merge_stripe = [&](size_t i, int) {
                int y0 = int(int64_t(H) * int64_t(i) / stripes_), y1 = int(int64_t(H) * int64_t(i + 1) / stripes_);
                film_.merge(items_, n_items, y0, y1);
            };
            loop.parallel_commit(size_t(stripes_), merge_stripe);
            paths_done_ += chunk_paths;
        }
        return s1;
    }

    // The estimate of every light path in the film (after a cancel, more
    // than spp * W * H of them).
    void develop(int, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const override {
        film_.develop(paths_done_, image, variance, effects);
    }

    void finish(RenderOutput& out) const override {
        if (n_strat_ > 0) film_.develop_strategies(paths_done_, out.strategies, out.strategies_unweighted);
    }

private:
    // Light paths g in [a, b), each on Sampler(seed, g mod W H, g / (W H)),
    // their finite splats into `dst` with their batch.
    void trace_paths(PassLoop& loop, uint64_t a, uint64_t b, std::vector<ItemSplat>& dst, ThreadStats& stats) const {
        dst.clear();
        std::vector<Splat> splats;
        for (uint64_t g = a; g < b; ++g) {
            if (loop.cancelled()) return;
            splats.clear();
            if (plan_.independent()) {
                Sampler sampler(loop.seed(), g % pixels_, g / pixels_);
                integrator_.trace_light_path(scene_, sampler, int(g % pixels_), splats, stats);
            } else {
                PixelSampleSource source(plan_, g % pixels_, g / pixels_);
                Sampler sampler(&source);
                integrator_.trace_light_path(scene_, sampler, int(g % pixels_), splats, stats);
            }
            for (const Splat& s : splats)
                if (keep_finite(stats, s.value)) dst.push_back({s, batch_of(g, pixels_)});
        }
        loop.add_done(b - a);
    }

    const Scene& scene_;
    const Integrator& integrator_;
    const uint64_t pixels_;
    const int n_strat_;
    SplatFilm film_;
    const int stripes_;
    std::vector<std::vector<ItemSplat>> items_;
    const SamplerPlan& plan_;
    uint64_t paths_done_ = 0;  // light paths [0, paths_done_) are in the film
};

}  // namespace

RenderOutput render_light_paths(const Scene& scene, const Integrator& integrator, const RenderOptions& opts,
                                const PollFn& poll) {
    integrator.check_scene(scene);
    const SensorDesc& sd = scene.sensor_desc;
    int W = scene.sensor->width, H = scene.sensor->height;
    FilterSampler filter(sd.rfilter, sd.filter_radius, sd.filter_stddev);
    const int n_strat = integrator.strategy_depth() > 0 ? num_strategies(integrator.strategy_depth()) : 0;
    // The splat film's sums (effects, batches) and the strategy images'
    // sums and outputs, said up front (memory.h).
    const double pixels = double(W) * double(H);
    std::vector<MemoryPart> parts = {
        {"light-tracing films", pixels * 3.0 * (kNumEffects + kBatches) * sizeof(double),
         "the resolution (film width, height)"},
        {"strategy images", pixels * 3.0 * 2.0 * n_strat * (sizeof(double) + sizeof(float)), "strategy_images"},
        output_memory(opts, W, H)};
    check_memory(integrator.type, W, H, parts);
    PassLoop loop(scene, opts, poll);
    SamplerPlan plan(opts.sampler, opts.spp, W, H, opts.seed);
    LightStep step(scene, integrator, filter, n_strat, loop.threads(), plan);
    RenderOutput out = loop.run(step);
    out.sampler = plan.name();
    return out;
}

}  // namespace rm
