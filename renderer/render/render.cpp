#include "render/render.h"

#include <stdexcept>

namespace rm {

namespace {
// The estimators whose every BSDF query is made at a vertex reached from the
// camera (a normal map whose frame follows the arriving direction is right
// there); every other one is refused such a map.
bool camera_paths_only(const std::string& type) {
    for (const char* t : {"path", "volpath", "volpathmis", "direct", "whitted", "irrcache", "radcache"})
        if (type == t) return true;
    return false;
}
}  // namespace

RenderOutput Integrator::drive(const Scene&, const RenderOptions&, const PollFn&) const {
    throw std::logic_error("Integrator::drive called on an estimator that does not own its driver");
}

RenderOutput render(const Scene& scene, const Integrator& requested, const RenderOptions& opts, const PollFn& poll) {
    if (!scene.committed()) throw std::logic_error("render: scene is not committed");
    const Integrator& integrator = requested.for_scene(scene);
    if (opts.spp < 0) throw std::invalid_argument("render: spp must be >= 0");
    if (!(opts.seconds >= 0)) throw std::invalid_argument("render: seconds must be >= 0");
    if (opts.spp == 0 && opts.seconds <= 0) throw std::invalid_argument("render: give spp or seconds");
    if (scene.features.has_media && !integrator.supports_media())
        throw std::invalid_argument("integrator '" + integrator.type +
                                    "' does not support participating media yet, and this scene has media; "
                                    "use integrator 'volpath' (or 'path', the same estimator), 'bdpt', 'ptracer', or "
                                    "'photonmapper' (volume photon map and ray marching)");
    if (scene.features.has_dipole && !integrator.supports_dipole()) {
        std::string shape;
        for (const auto& s : scene.shapes)
            if (s->dipole >= 0) {
                shape = s->id;
                break;
            }
        throw std::invalid_argument("integrator '" + integrator.type +
                                    "' cannot render the dipole BSSRDF (subsurface "
                                    "'dipole' on shape '" +
                                    shape +
                                    "'): only the camera-path estimators sample its "
                                    "exit points; use integrator 'path' (or 'volpath')");
    }
    if (scene.features.has_incident_frame && !camera_paths_only(integrator.type)) {
        std::string shape;
        for (const auto& s : scene.shapes)
            if (scene.bsdfs[size_t(s->bsdf)]->frame_follows_wi()) {
                shape = s->id;
                break;
            }
        throw std::invalid_argument(
            "integrator '" + integrator.type + "' cannot render the normalmap/bumpmap of shape '" + shape +
            "' with flip_invalid_normals = true: that frame follows the direction a ray arrives from, which on a "
            "light path is the light's side, so light paths would see another surface than camera paths; set "
            "flip_invalid_normals = false, or use a camera-path integrator (path, volpath, direct, whitted, "
            "irrcache, radcache)");
    }
    LightSamplerUse lights(scene, requested.light_sampler);
    if (integrator.owns_driver()) return integrator.drive(scene, opts, poll);
    if (integrator.is_light_tracer()) return render_light_paths(scene, integrator, opts, poll);
    return render_camera_paths(scene, integrator, opts, poll);
}

}  // namespace rm
