// The one pass loop every render driver runs on: it owns the budget (spp,
// seconds on the steady clock), the pass plan, checkpoints, progress and
// cancellation, NaN/Inf accounting and the threads; a driver supplies one
// PassStep, the work of a pass of samples per pixel, and its estimate.
//
// Drivers on it: the camera driver (camera_driver.cpp: tiles of camera
// rays), the light driver (light_render.cpp: light paths splatted onto the
// film), and estimators with passes of their own (photonmapper: photon
// passes before the camera passes, the loop's setup; sppm: a photon pass in
// every pass). A new estimator gets budgets, checkpoints and Ctrl-C by
// implementing PassStep.
//
// Determinism: the pass plan under an spp budget depends on the budget and
// the checkpoints alone (next_pass_end), and a step must make a pass's
// result a function of the seed whatever the thread count (each work item
// draws on its own streams and results are combined in item order).
#pragma once
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "render/parallel.h"
#include "render/render.h"

namespace rm {

// Threads a render uses: opts.threads, or all hardware threads when 0.
int render_threads(const RenderOptions& opts);
// The checkpoints a render keeps: opts.checkpoints sorted, without repeats.
std::vector<int> checkpoint_plan(const RenderOptions& opts);
// End (exclusive sample index) of the next pass of samples per pixel after
// spp_done, or -1 when the budget is spent: the pass plan of every driver.
int next_pass_end(const RenderOptions& opts, const std::vector<int>& checkpoints, int spp_done, double elapsed,
                  double sec_per_spp);

class PassLoop;

// What a driver does in each pass of the loop.
class PassStep {
public:
    virtual ~PassStep() = default;
    // Renders samples [s0, s1) of every pixel on `loop`'s threads. Returns
    // s1 when the pass is complete; less means it was cancelled, and the
    // return value is the sample count per pixel that the estimate keeps.
    virtual int pass(PassLoop& loop, int s0, int s1) = 0;
    // The estimate after `spp` complete samples per pixel (after a cancel,
    // the step's estimate of everything it kept): image, variance of the
    // estimate, effect images when `effects` is given.
    virtual void develop(int spp, std::vector<float>& image, std::vector<float>& variance,
                         std::vector<std::vector<float>>* effects) const = 0;
    // The variance of each effect's estimate after `spp` samples per pixel,
    // for a step whose film keeps it (RenderOptions::effect_variance); the
    // default leaves `variance` empty: not known.
    virtual void develop_effect_variance(int spp, std::vector<std::vector<float>>& variance) const { variance.clear(); }
    // Adds what the step alone knows to the final output (photon maps,
    // per-strategy images, stats of its own).
    virtual void finish(RenderOutput& out) const {}
};

class PassLoop {
public:
    // Starts the clock: the time from here to run() (a driver's setup, such
    // as photon passes) counts against a time budget.
    PassLoop(const Scene& scene, const RenderOptions& opts, const PollFn& poll);

    const Scene& scene() const { return scene_; }
    const RenderOptions& options() const { return opts_; }
    uint64_t seed() const { return opts_.seed; }
    int threads() const { return threads_; }
    double elapsed() const;

    // Runs the passes that the budget allows and develops the estimate,
    // returned for the sensor's crop window (by default the film).
    RenderOutput run(PassStep& step);
    // The pixels whose samples a step counts with add_done (default: the
    // film's), for the progress total.
    void set_pixels(uint64_t pixels);
    // The output of a render cancelled during its setup: zero image, NaN
    // variance, no samples.
    RenderOutput cancelled_output() const;

    // fn(i, thread) for i in [0, n) on the threads while the calling thread
    // polls progress and cancellation; false when cancelled (items may then
    // be unfinished).
    template <class Fn>
    bool parallel_for(size_t n, Fn fn) {
        return run_parallel(threads_, n, fn, poll_once_, cancel_);
    }
    // The same, never cancelled and without polling: commits a finished
    // pass's results (film merges, photon gathers), so that a pass is
    // either wholly in the estimate or not at all.
    template <class Fn>
    void parallel_commit(size_t n, Fn fn) {
        std::atomic<bool> never{false};
        run_parallel(threads_, n, fn, [] { return true; }, never);
    }
    // Whether a poll asked to cancel (work items check it between samples).
    bool cancelled() const { return cancel_.load(std::memory_order_relaxed); }
    // One poll with the progress so far, for work that runs its own
    // parallel loops (photon tracing); false: cancel.
    const std::function<bool()>& poll_once() const { return poll_once_; }
    // Progress, in the units of `total` (samples of pixels, or light paths).
    void add_done(uint64_t n) { done_.fetch_add(n, std::memory_order_relaxed); }
    // Counters of thread `t` of parallel_for / parallel_commit.
    ThreadStats& stats(int t) { return stats_[size_t(t)].s; }

private:
    // Cache-line sized, so that threads counting side by side do not share lines.
    struct alignas(64) PaddedStats {
        ThreadStats s;
    };
    const Scene& scene_;
    RenderOptions opts_;
    PollFn poll_;
    int threads_;
    uint64_t total_;  // progress units of the whole render; 0 when only a time budget bounds it
    std::chrono::steady_clock::time_point t0_;
    std::atomic<bool> cancel_{false};
    std::atomic<uint64_t> done_{0};
    std::function<bool()> poll_once_;
    std::vector<PaddedStats> stats_;
};

// A NaN or Inf sample is counted and dropped, never written: true when `a`
// and `b` are finite; else counts one NaN sample (any channel NaN) or one
// Inf sample in `stats` and returns false.
inline bool keep_finite(ThreadStats& stats, const Color& a, const Color& b = Color(0.f)) {
    if (is_finite(a) && is_finite(b)) return true;
    bool nan =
        std::isnan(a.x) || std::isnan(a.y) || std::isnan(a.z) || std::isnan(b.x) || std::isnan(b.y) || std::isnan(b.z);
    if (nan)
        ++stats.nan_samples;
    else
        ++stats.inf_samples;
    return false;
}

// The camera passes of an estimator with passes of its own (photonmapper
// after its photon maps, radiosity after its solve), through the camera
// driver: `owner`'s name, capabilities (driver: camera) and effect mask,
// each camera ray handed to `shade`.
class CameraView final : public Integrator {
public:
    using Shade = std::function<void(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&)>;
    CameraView(const Integrator& owner, Shade shade) : shade_(std::move(shade)) {
        type = owner.type;
        caps = owner.caps;
        caps.driver = Driver::Camera;
        mask = owner.mask;
    }
    void sample(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out,
                ThreadStats& stats) const override {
        shade_(scene, sampler, ray, out, stats);
    }

private:
    Shade shade_;
};

// The per-pixel sums of an estimator with passes of its own (vcm, vpl,
// rowcolumn): each pass's estimate, by effect class, is written into the
// pass buffer (pass_pixel: kNumEffects x 3 doubles per pixel), then
// committed whole, so a cancelled pass leaves the sums untouched.
// develop(): the mean over passes, and as variance the sample variance
// over passes of each pass's estimate over their count (the passes as
// independent estimates).
class PassSums {
public:
    explicit PassSums(size_t pixels);
    void clear_pass();
    double* pass_pixel(size_t p) { return &iter_[p * kNumEffects * 3]; }
    void set(size_t pixel, const EffectRadiance& er);
    void commit();
    int passes() const { return passes_; }
    void develop(int n, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const;

private:
    size_t px_;
    std::vector<double> iter_, sum_, tot_, tot_sq_;
    int passes_ = 0;
};

// The camera driver on a loop (camera_driver.cpp): `integrator`'s sample()
// along filter-importance-sampled camera rays, tile by tile; photonmapper
// runs its camera passes through it after its photon passes.
RenderOutput render_camera_paths(PassLoop& loop, const Integrator& integrator);
// Camera rays in packets for the estimators that take their hits
// (Integrator::takes_camera_hits); off: one ray at a time, for the test
// that both give the same bytes (tests/test_rays.py). On by default.
void set_camera_packets(bool on);

}  // namespace rm
