// Plain descriptions of scene parts, filled by the Python loader (which has
// already resolved Mitsuba's defaults, named IORs, units and transforms) and
// turned into renderer objects by Scene. Everything here is in world space.
#pragma once
#include <array>
#include <map>
#include <string>
#include <vector>

#include "core/params.h"
#include "core/spectrum.h"
#include "scene/texture.h"

namespace rm {

using Matrix4 = std::array<double, 16>;  // row-major 4x4
inline Matrix4 identity4() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }

struct BsdfDesc {
    std::string type = "diffuse";       // diffuse conductor roughconductor dielectric roughdielectric
                                        // thindielectric plastic twosided null principled
                                        // principledthin blendbsdf
    std::string id;                     // for error messages
    Color reflectance{0.5f};            // diffuse
    Color diffuse_reflectance{0.5f};    // plastic
    Color specular_reflectance{1.f};    // conductor, dielectric, plastic
    Color specular_transmittance{1.f};  // dielectric
    Color eta{0.f}, k{1.f};             // conductor (relative to ext_ior); material "none" = (0, 1)
    float int_ior = 1.5046f, ext_ior = 1.000277f;
    float alpha_u = 0.1f, alpha_v = 0.1f;   // rough*: microfacet roughness
    std::string distribution = "beckmann";  // "beckmann" | "ggx"
    bool sample_visible = true;
    bool nonlinear = false;  // plastic
    std::vector<BsdfDesc>
        nested;  // twosided: 1 (both sides) or 2 (front, back); blendbsdf: 2; mask, normalmap, bumpmap: 1
    // principled, principledthin: base_color; their scalar parameters
    // (roughness, metallic, ..., the sampling rates) and blendbsdf's weight
    // by Mitsuba's names, defaults filled in by the loader; a textured one
    // also has its texture in `textures`, which then replaces the value.
    Color base_color{0.5f};
    std::map<std::string, float> floats;
    float opacity = 0.5f;                // mask, when not textured
    float scale = 1.f;                   // bumpmap: the height texture's scale
    bool flip_invalid_normals = true;    // normalmap, bumpmap (Mitsuba 3.7.1 on)
    bool use_shadowing_function = true;  // normalmap, bumpmap (Mitsuba 3.7.1 on)
    // Textured colour parameters: parameter name -> its texture, which then
    // replaces the plain value above (reflectance of diffuse,
    // diffuse_reflectance of plastic and roughplastic, specular_reflectance
    // of conductor and roughconductor); and the textures that are the
    // parameter: mask's "opacity" (read as eval_1), normalmap's "normalmap"
    // (tangent-space normals, RGB = (n + 1) / 2), bumpmap's "bumpmap" (a
    // height field, read as eval_1 and its uv gradient).
    std::map<std::string, TextureDesc> textures;
};

struct EmitterDesc {
    std::string type = "area";  // area point spot directional constant
    std::string id;
    Color radiance{1.f};             // area, constant
    Color intensity{1.f};            // point, spot
    Color irradiance{1.f};           // directional
    Matrix4 to_world = identity4();  // point/spot: position + frame (spot looks along +z)
    float cutoff_angle = 20.f;       // spot, degrees
    float beam_width = -1.f;         // spot, degrees; < 0: 3/4 of cutoff_angle (Mitsuba default)
    // projector: horizontal field of view (degrees; fov_axis resolved in
    // Python), the image's width / height, and `scale` on the irradiance.
    float fov_x = 90.f, aspect = 1.f, scale = 1.f;
    // envmap: a latitude-longitude image, env_height rows of env_width RGB
    // pixels (row 0 looks along local +y), radiance with `scale` applied;
    // to_world maps its local frame to the world.
    int env_width = 0, env_height = 0;
    std::vector<float> env_data;
    // Textures by parameter name: spot "texture" (projected along the beam,
    // multiplying the intensity; Mitsuba 3's spot), projector "irradiance"
    // (which then replaces the plain irradiance), area "radiance".
    std::map<std::string, TextureDesc> textures;
};

struct SensorDesc {
    std::string type = "perspective";  // perspective orthographic radiancemeter irradiancemeter
    Matrix4 to_world = identity4();
    float fov_x = 39.3077f;  // horizontal field of view in degrees (fov_axis resolved in Python)
    float near_clip = 1e-2f, far_clip = 1e4f;
    int width = 256, height = 256;
    // The crop window (Mitsuba's film crop_offset_x/y, crop_width/height):
    // the pixels rendered and returned; width/height keep the geometry.
    // crop_width/height 0: the full film.
    int crop_x = 0, crop_y = 0, crop_width = 0, crop_height = 0;
    std::string rfilter = "gaussian";  // box tent gaussian
    float filter_radius = 2.f;         // box: 0.5, tent: 1, gaussian: 4 * stddev
    float filter_stddev = 0.5f;        // gaussian
    int shape = -1;                    // irradiancemeter: index of the shape it measures
    int medium = -1;                   // index of the medium the sensor sits in (-1: vacuum)
};

// A participating medium (Mitsuba 3's `homogeneous`): the loader resolves
// sigma_t + albedo or sigma_a + sigma_s, and `scale`, into these two.
// A grid volume (Mitsuba 3's `gridvolume`): nx * ny * nz voxels of
// `channels` (1 or 3) floats, x fastest, over the unit cube of its local
// space; `to_world` maps that cube into the world. Trilinear, clamped.
struct GridDesc {
    int nx = 0, ny = 0, nz = 0, channels = 1;
    std::vector<float> data;
    Matrix4 to_world = identity4();
    // Mitsuba's `accel`: a majorant grid for the tracking of a sigma_t grid
    // (Medium); false: one global majorant per channel.
    bool accel = true;
};

struct MediumDesc {
    std::string type = "homogeneous";  // homogeneous | heterogeneous
    std::string id;                    // for error messages
    Color sigma_t{1.f};                // extinction per unit length, scale applied
    Color albedo{0.75f};               // sigma_s / sigma_t, in [0, 1]
    // heterogeneous: a grid (nx > 0) replaces the constant above; the
    // medium's `scale` is applied to sigma_t_grid's values by the renderer.
    GridDesc sigma_t_grid, albedo_grid;
    float scale = 1.f;
    std::string phase = "isotropic";  // isotropic | hg
    float g = 0.f;                    // hg asymmetry, in (-1, 1)
};

// An integrator as the scene names it: the estimator and its parameters as
// given. The estimator's declaration (render/registry.h) checks them and
// fills in its defaults.
struct IntegratorDesc {
    std::string type = "path";
    ParamSet params;
};

}  // namespace rm
