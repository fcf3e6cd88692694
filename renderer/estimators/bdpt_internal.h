// What bdpt's test hook (bdpt_mis_check.cpp) needs of bdpt's production
// code (bdpt.cpp), and nothing else: the two subpaths of one sample as the
// renderer draws them, and the renderer's MIS weight of a strategy over
// them. Internal to the estimators; the bindings see only
// integrator.h's bdpt_mis_check.
#pragma once
#include <memory>
#include <vector>

#include "render/integrator.h"
#include "transport/subpath.h"

namespace rm {

class BdptMisProbe {
public:
    virtual ~BdptMisProbe() = default;
    // The camera and light subpaths of sample `pixel` as trace_light_path
    // draws them, into cam() and light() (the renderer's thread-local ones).
    virtual void generate_subpaths(const Scene& scene, Sampler& sampler, int pixel) const = 0;
    virtual std::vector<PathVertex>& cam() const = 0;
    virtual std::vector<PathVertex>& light() const = 0;
    // bdpt's weight of strategy (s, t) for the subpaths now in cam() and light().
    virtual float mis_weight(const Scene& scene, int s, int t) const = 0;
    // The heuristic's exponent, h(r) = r^e: 0 uniform, 1 balance, beta power.
    virtual double heuristic_exponent() const = 0;
    virtual int max_depth() const = 0;
};

// A bdpt integrator of desc `d`, checked against `scene` (check_scene).
std::unique_ptr<BdptMisProbe> make_bdpt_mis_probe(const Scene& scene, const Integrator& bdpt);

// Multiplexed MLT's use of bdpt (pssmlt.cpp's mmlt): strategy (s, t) alone
// on subpaths of s and t vertices, its weighted contribution times
// n_strategies appended to `out` (trace_light_path's splat conventions).
// `bdpt` must be a bdpt integrator checked against `scene` (check_scene).
void bdpt_trace_strategy(const Integrator& bdpt, const Scene& scene, Sampler& sampler, int pixel, int s, int t,
                         float n_strategies, std::vector<Splat>& out, ThreadStats& stats);

}  // namespace rm
