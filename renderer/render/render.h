// The render entry point and what it returns. render() checks the scene
// against the estimator and hands it to its driver: the camera driver
// (camera_driver.cpp), the light driver (light_render.cpp), or the
// estimator's own passes (Integrator::drive); all of them run on the one
// pass loop (pass_loop.h), which owns budgets, checkpoints, progress and
// cancellation. Results are identical for a given seed whatever the thread
// count.
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "render/integrator.h"

namespace rm {

struct RenderOptions {
    int spp = 16;        // samples per pixel; with seconds > 0 an upper bound (0: none)
    double seconds = 0;  // wall-clock budget (steady clock); 0 = none
    uint64_t seed = 0;
    int threads = 0;               // 0 = all hardware threads
    std::vector<int> checkpoints;  // spp counts at which to keep a snapshot
    bool effect_variance = false;  // also the variance of each effect's estimate (camera driver)
};

struct Checkpoint {
    int spp = 0;
    double seconds = 0;
    std::vector<float> image, variance;
};

// A photon map a render built (photon mapping estimators), for res.stats.
struct PhotonMapStats {
    std::string name;             // "caustic", "global", "sppm"
    uint64_t photons = 0;         // photons stored
    uint64_t paths = 0;           // light paths traced to store them (the power normaliser)
    double bytes_per_photon = 0;  // memory of the map per photon
    double trace_seconds = 0, build_seconds = 0;
    bool target_reached = true;  // false: tracing gave up before storing the requested count
    uint64_t target = 0;         // photons requested (photonmapper's maps; 0 for sppm's)
    uint64_t max_paths = 0;      // the give-up bound on paths (photon_trace.h; 0 for sppm's)
};

struct RenderOutput {
    int width = 0, height = 0, spp = 0;
    double seconds = 0;
    bool cancelled = false;
    std::vector<float> image, variance;
    std::vector<std::vector<float>> effects;  // kNumEffects images
    // Variance of each effect's estimate (kNumEffects images) when asked for
    // and the driver keeps it; empty otherwise.
    std::vector<std::vector<float>> effect_variance;
    // Per strategy (strategy_index order, integrator.h), when asked for: the
    // MIS-weighted contributions (they sum to the image over all strategies)
    // and the unweighted ones (each alone an estimate of its depth's light).
    std::vector<std::vector<float>> strategies, strategies_unweighted;
    // vcm's merge techniques beside them, keyed (i, t): the merge of light
    // vertex y_i at camera vertex z_{t-1} (merge_keys[k] for images k).
    std::vector<std::array<int, 2>> merge_keys;
    std::vector<std::vector<float>> merges, merges_unweighted;
    std::vector<Checkpoint> checkpoints;
    ThreadStats stats;
    std::vector<PhotonMapStats> photon_maps;
    // Figures of the estimator's own for res.stats (name, values): one
    // value becomes a number, more a list (Metropolis' acceptance per chain).
    std::vector<std::pair<std::string, std::vector<double>>> estimator_stats;
    int threads = 0;
    double setup_seconds = 0;
};

// Called about every 50 ms from the calling thread with (done, total) sample
// counts (total 0 when only a time budget bounds the render); returning false
// cancels the render, which then returns what it finished.
using PollFn = std::function<bool(uint64_t done, uint64_t total)>;

RenderOutput render(const Scene& scene, const Integrator& integrator, const RenderOptions& opts, const PollFn& poll);

// The driver of camera estimators (Integrator::sample along camera rays).
RenderOutput render_camera_paths(const Scene& scene, const Integrator& integrator, const RenderOptions& opts,
                                 const PollFn& poll);

// The driver of light-tracing estimators (integrator.is_light_tracer()):
// light paths splatted onto the film (light_render.cpp).
RenderOutput render_light_paths(const Scene& scene, const Integrator& integrator, const RenderOptions& opts,
                                const PollFn& poll);

}  // namespace rm
