// `whitted`: Whitted ray tracing (Whitted 1980, "An Improved Illumination
// Model for Shaded Display"), the seed's starting point: camera rays follow
// delta reflection and refraction, and every surface with a smooth lobe
// takes direct light from the emitters (point, spot, directional, area,
// environment) by light sampling, with a shadow ray, and ends the path. So
// it renders exactly the paths L E, L D E and L D? S+ E: emission,
// direct, and what mirrors and glass show of those; indirect diffuse light
// and caustics (L S+ D E) are missing by construction, the model error a
// user of this estimator accepts.
// Where Whitted traces both a reflected and a refracted ray at a dielectric,
// one of them is sampled by the BSDF's own lobe selection (its Fresnel
// term) with weight f / pdf: the same expectation without a ray tree that
// doubles at every glass surface (pbrt-v3's WhittedIntegrator recurses into
// both, SpecularReflect and SpecularTransmit).
// Parameters: the registration below (pbrt-v3's `maxdepth`, default 5).
#include "render/registry.h"
#include "transport/common.h"

namespace rm {

namespace {

class WhittedIntegrator final : public Integrator {
public:
    WhittedIntegrator(int max_depth, bool hide) : max_depth_(max_depth), hide_(hide) {}

    void sample(const Scene& scene, Sampler& sampler, const Ray& camera_ray, EffectRadiance& out,
                ThreadStats& stats) const override {
        // Emission is counted along the chain without an MIS weight: seen
        // directly or through delta lobes only, no other technique reaches
        // emitters from there. A sampled smooth lobe ends the path.
        walk_specular_chain(
            scene, sampler, camera_ray, SpecularChain{max_depth_, -1, hide_}, mask, out, stats,
            [&](const Interaction& it, const Bsdf& bsdf, const Vec3& wi, const Color& beta, const PathClass& pc, int) {
                if (!pc.can_reach(mask)) return false;
                // A smooth lobe: direct light by light sampling alone
                // (bsdf fraction 0: the power heuristic's weight is then 1).
                if (bsdf.has_smooth()) {
                    PathClass pn = pc;
                    pn.push(false);
                    if (mask[pn.classify()])
                        out.add(pn.classify(), beta * estimate_direct(scene, it, bsdf, wi, sampler, stats, 1.f, 0.f));
                    else  // keep the random stream aligned whatever the mask is (a light sample draws 4)
                        sampler.next_1d(), sampler.next_2d(), sampler.next_1d();
                }
                return true;
            });
    }

private:
    int max_depth_;
    bool hide_;
};

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "whitted";
    e.doc =
        "Whitted ray tracing (1980): delta reflection and refraction, direct light at smooth surfaces; "
        "no indirect light, no caustics";
    e.params = {
        ParamSpec::integer("max_depth", 5, "longest path in segments (pbrt-v3's maxdepth)").at_least(1).at_most(1024),
        hide_emitters_param(),
    };
    e.caps.driver = Driver::Camera;
    e.caps.effects = effect_mask({kEmission, kDirect});  // L D S+ E only part of `specular`
    e.factory = [](ParamReader& p) {
        int max_depth = p.get_int("max_depth");
        return std::make_unique<WhittedIntegrator>(max_depth, p.get_bool("hide_emitters"));
    };
    return e;
}());

}  // namespace

}  // namespace rm
