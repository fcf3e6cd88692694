// Plain descriptions of scene parts, filled by the Python loader (which has
// already resolved Mitsuba's defaults, named IORs, units and transforms) and
// turned into renderer objects by Scene. Everything here is in world space.
#pragma once
#include <array>
#include <string>
#include <vector>

#include "core/spectrum.h"

namespace rm {

using Matrix4 = std::array<double, 16>;  // row-major 4x4
inline Matrix4 identity4() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }

struct BsdfDesc {
    std::string type = "diffuse";  // diffuse conductor roughconductor dielectric roughdielectric
                                   // thindielectric plastic twosided null
    std::string id;                // for error messages
    Color reflectance{0.5f};              // diffuse
    Color diffuse_reflectance{0.5f};      // plastic
    Color specular_reflectance{1.f};      // conductor, dielectric, plastic
    Color specular_transmittance{1.f};    // dielectric
    Color eta{0.f}, k{1.f};               // conductor (relative to ext_ior); material "none" = (0, 1)
    float int_ior = 1.5046f, ext_ior = 1.000277f;
    float alpha_u = 0.1f, alpha_v = 0.1f; // rough*: microfacet roughness
    std::string distribution = "beckmann";  // "beckmann" | "ggx"
    bool sample_visible = true;
    bool nonlinear = false;               // plastic
    std::vector<BsdfDesc> nested;         // twosided: 1 (both sides) or 2 (front, back)
};

struct EmitterDesc {
    std::string type = "area";  // area point spot directional constant
    std::string id;
    Color radiance{1.f};    // area, constant
    Color intensity{1.f};   // point, spot
    Color irradiance{1.f};  // directional
    Matrix4 to_world = identity4();  // point/spot: position + frame (spot looks along +z)
    float cutoff_angle = 20.f;       // spot, degrees
    float beam_width = -1.f;         // spot, degrees; < 0: 3/4 of cutoff_angle (Mitsuba default)
};

struct SensorDesc {
    std::string type = "perspective";  // perspective orthographic radiancemeter irradiancemeter
    Matrix4 to_world = identity4();
    float fov_x = 39.3077f;  // horizontal field of view in degrees (fov_axis resolved in Python)
    float near_clip = 1e-2f, far_clip = 1e4f;
    int width = 256, height = 256;
    std::string rfilter = "gaussian";  // box tent gaussian
    float filter_radius = 2.f;         // box: 0.5, tent: 1, gaussian: 4 * stddev
    float filter_stddev = 0.5f;        // gaussian
    int shape = -1;                    // irradiancemeter: index of the shape it measures
};

struct IntegratorDesc {
    std::string type = "path";  // direct path
    int max_depth = -1;         // Mitsuba's meaning; -1 = unbounded
    int rr_depth = 5;
    bool hide_emitters = false;
    // direct: sample counts per strategy (Mitsuba's direct integrator)
    int emitter_samples = 1, bsdf_samples = 1;
    // bdpt: MIS heuristic ("power", "balance", "uniform") and the power heuristic's exponent
    std::string mis = "power";
    float beta = 2.f;
    // photonmapper (Mitsuba 0.6's names in camelCase; radii relative to the
    // radius of the scene's bounding sphere, as Mitsuba's are to the scene size)
    int direct_samples = 16;         // directSamples
    int global_photons = 250000;     // globalPhotons
    int caustic_photons = 250000;    // causticPhotons
    float global_lookup_radius = 0.05f;     // globalLookupRadius
    float caustic_lookup_radius = 0.0125f;  // causticLookupRadius
    int lookup_size = 120;           // lookupSize
    int gather_rays = 32;            // final-gathering rays per camera sample
    bool final_gather = true;        // false: the global map seen directly (shows its bias)
    // sppm (Mitsuba 0.6: photonCount, initialRadius, alpha)
    int photon_count = 250000;       // photons emitted per pass
    float initial_radius = 0.f;      // world units; 0 = automatic
    float alpha = 0.7f;
};

}  // namespace rm
