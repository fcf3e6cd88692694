"""Scene loader: Mitsuba 3 scene dicts and XML files -> `SceneDesc`.

Written here rather than taken from a library: no maintained package reads
Mitsuba 3's XML/dict formats without Mitsuba itself, which must stay
optional. PLY files go through the maintained `plyfile` package. OBJ has a
small reader of our own (_read_obj) because the maintained readers change
the mesh: meshio drops the texture and normal indices of OBJ faces, trimesh
merges vertices (and needs PIL for a textured OBJ); neither splits vertices
per distinct v/vt/vn triple as Mitsuba does, which the tests check against
Mitsuba's own buffers.

`load_dict(d)` takes the dict that `mitsuba.load_dict` takes, `load_file(path,
**params)` a Mitsuba 3 XML file; both resolve what Mitsuba leaves implicit
(defaults, named IORs, `ref`s, transforms, fov_axis) into the dataclasses of
`scene_desc.py`. Mitsuba 3.9.1 is the reference for every default and
convention below; anything outside this subset, any parameter a plugin does not
use, a wrong type or a bad value raises `SceneError` naming the element and its
place: `scene.xml:12: bsdf 'diffuse': unknown parameter 'reflectanse'`, or for
dicts the key path, `scene['floor']['bsdf']['reflectance']: bsdf 'diffuse':
negative value -0.1`.

Both front ends (from_dict.py, from_xml.py) turn their input into one
intermediate form (nodes.py: a node per plugin instance with its
parameters); build.py makes the descriptions from it, reading parameters
through parameters.py, meshes and volumes through meshes.py and volumes.py,
with the transforms of transforms.py; plugins.py is the table of accepted
plugin types.

Supported plugins and their parameters (defaults in brackets)
-------------------------------------------------------------
shape      obj, ply: filename, face_normals [false], flip_normals [false],
               to_world, obj also flip_tex_coords [true]. Faces are fans of
               polygons (OBJ) or triangles only (PLY, as Mitsuba). Vertex
               normals from the file are kept; without any and without
               face_normals they are recomputed, angle-weighted, as Mitsuba does.
           rectangle: [-1,1]^2 at z=0, normal +z; to_world, flip_normals
               (face_normals accepted: a flat shape has no other normals).
           cube: [-1,1]^3, 24 vertices, outward normals per face;
               to_world, flip_normals, face_normals.
           disk (analytic): to_world, flip_normals.
           sphere (analytic): center [0], radius [1], to_world (no shear or
               non-uniform scale), flip_normals.
           cylinder (analytic, open tube): radius [1], p0 [0,0,0], p1
               [0,0,1], to_world (no shear, equal x and y scales),
               flip_normals; uv = (phi / 2 pi, z / length).
           serialized (Mitsuba's zlib-compressed format, versions 3 and 4):
               filename, shape_index [0], face_normals [false], to_world,
               flip_normals.
           shapegroup: shapes in the group's own space, drawn only through
               instances (no emitter, sensor, subsurface or nested
               shapegroup/instance inside, as Mitsuba); instance: one nested
               or referenced shapegroup, to_world (Embree instancing: the
               group is traced once, normals by the inverse transpose).
           sdfgrid is refused by name.
           Each shape may nest one bsdf, one area emitter and one
           irradiancemeter sensor.
bsdf       diffuse: reflectance [0.5]
           conductor: material ['none': eta 0, k 1] or eta [0] + k [1],
               specular_reflectance [1]
           roughconductor: as conductor + distribution ['beckmann'|'ggx'],
               alpha [0.1] or alpha_u + alpha_v, sample_visible [true]
           dielectric, thindielectric: int_ior ['bk7'], ext_ior ['air'],
               specular_reflectance [1], specular_transmittance [1]
           roughdielectric: as dielectric + the microfacet parameters
           plastic: diffuse_reflectance [0.5], specular_reflectance [1],
               int_ior ['polypropylene'], ext_ior ['air'], nonlinear [false]
           roughplastic: as plastic + distribution ['beckmann'|'ggx'],
               alpha [0.1] (alpha_u + alpha_v only if equal: isotropic, as
               Mitsuba), sample_visible [true]; int_ior != ext_ior
           twosided: one or two nested reflective bsdfs (as Mitsuba: not
               dielectric, thindielectric, roughdielectric, null or mask, nor
               a normalmap or bumpmap); null: none.
           mask: opacity [0.5] (a float or a texture, read as eval_1) + one
               nested bsdf: pass-through with probability 1 - opacity.
           normalmap: normalmap (a texture of tangent-space normals, usually
               a raw bitmap) + one nested bsdf; bumpmap: one texture of any
               name (a height field) + scale [1] + one nested bsdf. Both:
               flip_invalid_normals [true] (then only camera-path
               integrators render it), use_shadowing_function [true], as
               Mitsuba 3.9 (docs/normalmap.md).
           An IOR is a float or one of the names in NAMED_IOR (any case).
           A shape without a bsdf gets Mitsuba 3's default: diffuse 0.5, or
           diffuse 0 (black) when it carries an area emitter.
texture    rawconstant: value (a float or a 3-vector, as given).
           checkerboard: color0 [0.4], color1 [0.2] (colours, not nested
               textures), to_uv (a transform; Mitsuba's 3x3 uv map from its
               rows and columns x, y and translation).
           bitmap: filename (.png/.jpg through Pillow, decoded from sRGB to
               linear unless raw [false]; .exr through the OpenEXR package, as
               stored; grey images keep one channel, alpha is dropped),
               filter_type ['bilinear'|'nearest'], wrap_mode ['repeat'|
               'mirror'|'clamp'], to_uv, format, accel (accepted: storage
               and GPU hints). .bmp as .png.
           rawconstant: value (a float or a 3D vector), taken as it is.
           mesh_attribute: name (vertex_* or face_*), scale [1]: a PLY
               mesh's attribute (other vertex and face properties, grouped
               as Mitsuba does: NAME_0.. -> vertex_NAME / face_NAME, r g b
               -> vertex_color, integers as they are; 1 or 3 channels),
               vertex attributes interpolated with the barycentrics; every
               shape it is used on must have the attribute (else a
               SceneError at its 'name').
           A texture is nested under the parameter's name or referenced
           (<ref name=".." id=".."/>; top-level textures are declarations).
           It takes the place of diffuse.reflectance,
           plastic/roughplastic.diffuse_reflectance,
           conductor/roughconductor.specular_reflectance,
           roughconductor.alpha / alpha_u / alpha_v (read as one number,
           Mitsuba's eval_1: a checkerboard's squares swap there, as in
           Mitsuba 3.9.1), area.radiance, spot.texture and
           projector.irradiance (parameters.TEXTURED);
           on any other parameter it is a SceneError naming the plugin, the
           parameter and the place. Evaluated at the hit's uv: OBJ/PLY
           vertex uvs (OBJ's v flipped unless flip_tex_coords is false),
           the rectangle's ((x+1)/2, (y+1)/2), the cube's per-face uvs, the
           disk's (r, phi / 2 pi) and the sphere's (phi / 2 pi, theta / pi)
           in its object frame, all as Mitsuba 3 defines them. A shape
           whose bsdf is anisotropic (alpha_u != alpha_v, or textured
           alphas) gets Mitsuba's shading tangent, dp/du; others keep theirs.
colours   rgb, float, or spectrum: wavelength:value pairs or an .spd file,
           converted as Mitsuba 3's RGB variants do (spectra.py); a uniform
           spectrum is its value, except on an emitter, where it is XYZ
           (v, v, v) in sRGB as in Mitsuba.
emitter    area (nested in a shape): radiance [1] (a colour or a texture,
               read at the uv of the emitting point; points are still
               sampled uniformly by area)
           point: intensity [1], position or to_world
           spot: intensity [1], cutoff_angle [20], beam_width [3/4 cutoff],
               to_world (shines along +z), texture (a nested texture
               projected along the beam, at Mitsuba's uv 1/2 + (x, y) /
               (2 z tan cutoff), multiplying the intensity)
           projector: irradiance [1] (a colour or a texture: the image on
               the plane z = 1), scale [1], fov + fov_axis or focal_length
               (as the perspective sensor's, with the texture's width /
               height for aspect), to_world (no scale; shines along +z).
               Mitsuba 3's intensity scale pi E(uv) / cos^3 at its
               sample-space uv (renderer/scene/emitter.cpp).
           directional: irradiance [1], direction or to_world
           constant: radiance [1]
           envmap: filename (a latitude-longitude image: .exr through the
               OpenEXR package, .png/.jpg through Pillow, sRGB to linear;
               at least 2x3 pixels, finite, non-negative), scale [1],
               to_world, mis_compensation [false] (only false). Mitsuba's
               lat-long convention and bilinear lookup; importance-sampled
               (renderer/scene/emitter.cpp).
           The other Mitsuba 3 emitters (all but envmap and projector) take
           no 'scale' parameter (3.9.1 rejects it as unreferenced), so
           neither do we: scale the radiance.
sensor     perspective: fov + fov_axis ['x'|'y'|'diagonal'|'smaller'|
               'larger'] or focal_length ['50mm', a string as in Mitsuba],
               near_clip [1e-2], far_clip [1e4], to_world (no scale); accepted
               and ignored because they change nothing for a pinhole camera:
               PERSPECTIVE_IGNORED.
           orthographic: to_world (its scale sets the extent), near_clip,
               far_clip.
           radiancemeter: to_world or origin + direction; needs a 1x1 film.
           irradiancemeter: only nested in a shape; it measures one value,
               so a film other than 1x1 warns (Mitsuba fills each pixel
               with an independent estimate).
           Each sensor may nest a film and a sampler.
film       hdrfilm: width [768], height [576] (1..16384), pixel_format
               ['rgb'|'rgba'], component_format ['float16'|'float32'], rfilter;
               crop_offset_x/y [0], crop_width/height [the film's]: only
               the window's pixels are rendered and returned, with the
               full film's geometry and each pixel's own random streams
               (a crop is byte for byte that window of the full render
               with the box filter); sample_border [false]: samples stay
               in the window; true only with the box filter (Mitsuba's
               border is then empty).
rfilter    box (radius 0.5), tent: radius [1], gaussian: stddev [0.5]
               (radius = 4 stddev).
sampler    independent, stratified, multijitter, sobol, zsobol, ldsampler (rendered
               by sobol) (radiometer.samplers):
               sample_count [4] -> SensorDesc.spp, seed (accepted; render()'s
               seed decides), jitter [true] (stratified, multijitter).
integrator moment: its one nested integrator (Mitsuba's moment adds
               per-pixel moments; RenderResult.variance is always there).
integrator every estimator the core registers (radiometer.registry); its
           parameters (ints, floats, bools, strings; integers within 32 bits)
           are checked against the estimator's declaration at load, so that
           errors carry the file:line, and kept as given in IntegratorDesc.params.
medium     homogeneous: sigma_t [1] + albedo [0.75] (Mitsuba 3), or sigma_a +
               sigma_s (Mitsuba 0.6's form; albedo = sigma_s / sigma_t, 0
               where sigma_t is 0), scale [1] multiplying the coefficients;
               each an rgb or a float; sample_emitters [true] (only true);
               one nested phase [isotropic]. Nested in a shape as `interior`
               / `exterior` (or referenced by those names), in a sensor as
               `medium`; declared at the top level for refs.
           heterogeneous: as homogeneous, but sigma_t and albedo may each be
               a nested volume of that name; has_spectral_extinction
               accepted. The renderer tracks it against a majorant grid of
               a sigma_t gridvolume (its `accel`; delta tracking, ratio
               tracking for shadow rays), else one global majorant.
volume     gridvolume: filename (Mitsuba's .vol, version 3, float32, 1 or 3
               channels), to_world (maps the unit cube), use_grid_bbox
               [false], filter_type ['trilinear'], wrap_mode ['clamp'], raw,
               accel [true] (as sigma_t: a majorant grid for tracking; false:
               one global majorant); constvolume: value [1], to_world (it
               places the volume's box, the unit cube: a heterogeneous medium
               exists only inside its sigma_t volume's box, constant or
               grid, as Mitsuba 3's; a plain sigma_t value is a constvolume
               over [0, 1]^3 there too).
phase      isotropic; hg: g [0.8] in (-1, 1).
subsurface dipole (Mitsuba 0.6's plugin; nested in a shape, which it turns
               into a smooth dielectric boundary over a dipole BSSRDF, Jensen
               et al. 2001; renderer/scene/dipole.h): sigma_a + sigma_s, or
               sigma_t + albedo (albedo = sigma_s / sigma_t), each an rgb or a
               float, per unit length; sigma_s is the scattering coefficient
               itself, NOT the reduced one: sigma_s' = sigma_s (1 - g) with g
               [0] in (-1, 1); scale [1] multiplies the coefficients;
               int_ior ['bk7'], ext_ior ['air'] (IORs as for dielectric).
               Mitsuba 0.6's camelCase names (sigmaA, sigmaS, sigmaT, intIOR,
               extIOR) are accepted as aliases; irrSamples (its
               irradiance cache's density) is refused, naming why: exit
               points are sampled per path here. Its material presets are
               not supported. The shape may nest no bsdf (a smooth
               dielectric of the dipole's IORs is made), a `dielectric` of
               the same IORs, or, as Mitsuba 0.6's documentation sets it up,
               a `plastic` of the same IORs with diffuse_reflectance 0 (only
               its Fresnel reflection: the same boundary); no interior
               medium. Only the `path` and `volpath` integrators render it;
               the others refuse the scene.

XML file structure (as Mitsuba 3's src/core/xml.cpp)
----------------------------------------------------
- Every version 'a.b.c' loads; a file older than 2.0.0 is first upgraded as
  Mitsuba upgrades it (parameter names to underscore_case, <lookAt>, a
  diffuse bsdf's diffuse_reflectance), so Mitsuba 0.6 files read the same.
- <path value="..."/> (top level) puts a folder before the others on the
  search list of relative file names (meshes, volumes, includes); the
  scene's folder comes last. Mitsuba also searches the working directory
  before it; here a scene means the same wherever it is loaded.
- <include filename="..."/> (anywhere): an included <scene>'s children take
  its place, another root element is that element; errors inside it name
  the included file and line; a cycle, includes nested deeper than 15
  levels (Mitsuba's limit) or more than 1000 included files in all are
  refused.

Decisions where Mitsuba leaves a choice (see also the functions' comments)
-------------------------------------------------------------------------
- A scene without a sensor gets Mitsuba's default `perspective` (50 mm focal
  length on the diagonal, 768x576, gaussian filter, 4 spp, identity to_world);
  Mitsuba 3.9.1 itself leaves such a scene without a sensor. More than one
  sensor is an error (the renderer renders one).
- An irradiancemeter is stored both in its `ShapeDesc.sensor` and as
  `SceneDesc.sensor` (the same object).
- Meshes are in world space, so their `ShapeDesc.to_world` is the identity. A
  sphere's `to_world` is the full object-to-world map of the unit sphere,
  rotation included (radius * Q | center), consistent with `center`/`radius`; a
  mirroring to_world turns a sphere's normals inward, as in Mitsuba.
- A directional emitter's `to_world` is an orthonormal frame whose +z column is
  the (normalised) direction of travel of the light.
- Point and spot emitters store their position as the to_world translation.

Hostile input
-------------
Numbers in XML are decimal and ASCII ('1_6', which Python's int() reads as 16,
is refused); dict arrays hold real numbers only (no booleans, strings or
complex numbers, which numpy would convert); plugins nest at most _MAX_DEPTH
levels; a float parameter lies within float32's range (|x| <= 3.4e38, what
the renderer computes in), and so do mesh vertices after their to_world.
`load_file(path, base_dir_only=True)` (`radiometer render --untrusted`) is for
scenes from an untrusted source: every referenced file (meshes, volumes,
<include>d files, <path> folders) must resolve, through '..' and symbolic
links, to a file inside the scene's folder; messages then quote nothing read
from those files; the XML may not declare a DTD. Without it, as in Mitsuba,
a scene may name any readable file, and parse errors quote the offending line.
"""
from __future__ import annotations

from ..scene_desc import SceneError
from .build import SceneWarning
from .from_dict import load_dict
from .from_xml import load_file
from .parameters import NAMED_IOR, PERSPECTIVE_IGNORED
from .plugins import PLUGINS
from .volumes import write_vol

__all__ = ["load_dict", "load_file", "SceneError", "SceneWarning", "NAMED_IOR", "PERSPECTIVE_IGNORED", "PLUGINS",
           "write_vol"]
