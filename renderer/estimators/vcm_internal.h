// What vcm's test hook (vcm_mis_check.cpp) needs of vcm's production code
// (vcm.cpp): the recursive MIS quantities of a subpath vertex, the weights
// of every technique computed from them, and the subpaths of one sample as
// the renderer draws them. Internal to the estimators.
#pragma once
#include <cmath>
#include <memory>
#include <vector>

#include "render/integrator.h"
#include "transport/subpath.h"

namespace rm {

// The partial MIS quantities of one subpath vertex (Georgiev, Krivanek,
// Davidovic and Slusallek 2012, "Implementing Vertex Connection and
// Merging", tech. rep. eqs. (31)-(36): d^VCM, d^VC, d^VM), here in area
// measure: every density is the walk's pdf_fwd / pdf_rev (subpath.h), the
// ones bdpt's weights read, instead of the report's solid-angle split
// (SmallVCM's vertexcm.hxx divides the area conversion between vertices;
// the quantities are the same products).
struct VcmMis {
    double dvcm = 0, dvc = 0, dvm = 0;
};

// The techniques of one iteration and their weights. A full path
// x_0 (light) .. x_k (camera) has the connections (s light vertices, t =
// k + 1 - s camera vertices: s = 0 the camera hits the emitter, s = 1 next
// event estimation, t = 1 light tracing onto the film) and the merges at
// its non-delta surface vertices x_1 .. x_{k-1}; with n_L light paths per
// iteration, light tracing and merging count n_L samples per camera path
// and a merge is accepted with probability pi r^2 p(x_i) (the report's
// eta_VCM = pi r^2 n_L, eq. (20) with n_VC = 1, n_VM = n_L).
struct VcmWeights {
    bool vc = true, vm = true;  // connections (incl. s = 0, NEE, light tracing), merges
    bool balance = false;       // balance heuristic, else power with exponent beta
    float beta = 2.f;
    double eta = 1.0;          // pi r^2 n_L
    double n_light = 1.0;      // light paths per iteration
    double film_pixels = 1.0;  // W H: the camera's density per pixel is W H camera_pdf_a

    double h(double x) const { return balance ? x : (beta == 2.f ? x * x : std::pow(x, double(beta))); }
    // d^VCM, d^VC, d^VM of light vertex path[n] from those of path[n - 1]
    // (rec[0 .. n - 1] filled) and the densities the walk has set when
    // path[n] is made (its pdf_fwd, path[n - 2]'s pdf_rev).
    void light_update(const Scene& scene, const PathVertex* path, int n, VcmMis* rec) const;
    // The same for camera vertex cam[j], j >= 1.
    void camera_update(const PathVertex* cam, int j, VcmMis* rec) const;
    // The weight of each technique, for camera prefix cam[0 .. t-1] (and
    // its quantities crec) and light prefix light[0 .. s-1] (lrec).
    double emission(const Scene& scene, const PathVertex* cam, const VcmMis* crec, int t) const;
    double nee(const Scene& scene, const PathVertex* cam, const VcmMis* crec, int t, const PathVertex& y0) const;
    double connect(const Scene& scene, const PathVertex* cam, const VcmMis* crec, int t, const PathVertex* light,
                   const VcmMis* lrec, int s) const;
    double light_trace(const Scene& scene, const PathVertex& z0, const PathVertex* light, const VcmMis* lrec,
                       int s) const;
    // Merge of light vertex light[i] (i >= 1) at camera vertex cam[t - 1].
    double merge(const Scene& scene, const PathVertex* cam, const VcmMis* crec, int t, const PathVertex* light,
                 const VcmMis* lrec, int i) const;
};

// A vertex where merging can happen: a surface with a smooth lobe that the
// walk did not leave through a delta lobe.
inline bool vcm_mergeable(const PathVertex& v) {
    return v.type == VType::Surface && v.bsdf && v.bsdf->has_smooth() && !v.delta;
}

// A connection or merge end: a surface vertex with a smooth lobe.
inline bool vcm_mergeable_end(const PathVertex& v) {
    return v.type == VType::Surface && v.bsdf && v.bsdf->has_smooth();
}

class VcmMisProbe {
public:
    virtual ~VcmMisProbe() = default;
    // The weights of iteration `iteration` (its radius).
    virtual VcmWeights weights(const Scene& scene, int iteration) const = 0;
    // The camera and light subpaths of sample `pixel` of that iteration, with
    // their quantities, as the renderer draws them.
    virtual void generate(const Scene& scene, const VcmWeights& w, Sampler& cam_sampler, Sampler& light_sampler,
                          int pixel, std::vector<PathVertex>& cam, std::vector<VcmMis>& crec,
                          std::vector<PathVertex>& light, std::vector<VcmMis>& lrec) const = 0;
    virtual int max_depth() const = 0;
    virtual bool ppm() const = 0;
};

std::unique_ptr<VcmMisProbe> make_vcm_mis_probe(const Scene& scene, const Integrator& vcm);

}  // namespace rm
