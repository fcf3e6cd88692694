"""Triangle meshes: OBJ (our reader, Mitsuba's vertex splitting) and PLY
(plyfile) files, Mitsuba's rectangle and cube, vertex normals, and a mesh
ShapeDesc in world space."""
from __future__ import annotations

import math

import numpy as np

from ..scene_desc import SceneError
from .nodes import _quote
from .transforms import _apply_normals, _apply_points


def _vertex_normals(p, f):
    """Angle-weighted vertex normals, Thuermer and Wuethrich, "Computing Vertex
    Normals from Polygonal Facets", JGT 3(1), 1998: each face adds its unit
    normal times its angle at the vertex; degenerate faces add nothing and a
    vertex with no valid face gets (1, 0, 0), as Mitsuba's recompute."""
    p = p.astype(np.float64)
    v0, v1, v2 = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    n = np.cross(v1 - v0, v2 - v0)
    length = np.linalg.norm(n, axis=1)
    ok = length > 0
    n[ok] /= length[ok, None]
    n[~ok] = 0.0
    acc = np.zeros_like(p)
    corners = (v0, v1, v2)
    for j in range(3):
        e1 = corners[(j + 1) % 3] - corners[j]
        e2 = corners[(j + 2) % 3] - corners[j]
        l1 = np.linalg.norm(e1, axis=1)
        l2 = np.linalg.norm(e2, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cos = np.einsum("ij,ij->i", e1, e2) / (l1 * l2)
        angle = np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), -1.0, 1.0))
        np.add.at(acc, f[:, j], n * angle[:, None])
    length = np.linalg.norm(acc, axis=1)
    bad = ~(length > 0)
    acc[~bad] /= length[~bad, None]
    acc[bad] = (1.0, 0.0, 0.0)
    return acc.astype(np.float32)


def _read_obj(path, flip_tex_coords, err, quote=True):
    """Wavefront OBJ with Mitsuba's semantics: a vertex per distinct
    (position, texcoord, normal) index triple, numbered in order of first use;
    polygons as fans (v0, v[i-1], v[i]); 'vt' v flipped to 1 - v by default.
    Negative (relative) indices are rejected, as Mitsuba does. Statements
    other than v/vt/vn/f (o, g, s, usemtl, mtllib, l, #) are ignored.
    Numbers are decimal and finite (float() alone also takes '1_0', 'nan').
    quote=False: messages name the line but quote nothing of it (the file
    may be one an untrusted scene pointed at).

    Parsed here rather than with trimesh/meshio: meshio ignores the vt/vn
    indices of faces and trimesh merges vertices and needs PIL for texcoords,
    so neither reproduces Mitsuba's vertex splitting."""
    positions, texcoords, normals = [], [], []
    keys = {}
    tris = []
    try:
        fh = open(path, "r", encoding="utf-8", errors="replace")
    except OSError as e:
        raise SceneError(f"{err}: {path}: cannot read the OBJ file ({e.strerror})") from None

    def numbers(head, parts, count, lineno):
        vals = [float(x) for x in parts[:count]]
        if len(vals) != count or any(not x.isascii() or "_" in x for x in parts[:count]):
            raise ValueError
        if not all(math.isfinite(x) for x in vals):
            raise SceneError(f"{err}: {path}:{lineno}: non-finite value in a '{head}' statement")
        return vals

    with fh:
        for lineno, line in enumerate(fh, 1):
            parts = line.split()
            if not parts:
                continue
            head = parts[0]
            try:
                if head == "v":
                    positions.append(numbers(head, parts[1:], 3, lineno))
                elif head == "vn":
                    normals.append(numbers(head, parts[1:], 3, lineno))
                elif head == "vt":
                    texcoords.append(numbers(head, parts[1:], 2, lineno))
                elif head == "f":
                    ids = []
                    for tok in parts[1:]:
                        idx = tok.split("/")
                        if len(idx) > 3 or not tok.isascii() or "_" in tok:
                            raise ValueError
                        key = tuple(int(s) if s else 0 for s in idx) + (0,) * (3 - len(idx))
                        if key[0] < 1 or key[0] > len(positions) or min(key) < 0:
                            raise SceneError(f"{err}: {path}:{lineno}: face index "
                                             f"{_quote(tok) + ' ' if quote else ''}is out of range (only "
                                             f"positive indices of earlier vertices are supported)")
                        ids.append(keys.setdefault(key, len(keys)))
                    if len(ids) < 3:
                        raise SceneError(f"{err}: {path}:{lineno}: face with fewer than 3 "
                                         f"vertices")
                    for i in range(2, len(ids)):
                        tris.append((ids[0], ids[i - 1], ids[i]))
            except ValueError as e:
                if isinstance(e, SceneError):
                    raise
                # Unquoted, the line is named by its statement (one of the four above).
                what = _quote(line.strip()) if quote else f"(a '{head}' statement)"
                raise SceneError(f"{err}: {path}:{lineno}: cannot parse OBJ line {what}") from None
    if not tris:
        raise SceneError(f"{err}: {path}: the OBJ file has no faces")
    key_arr = np.array(list(keys), dtype=np.int64)
    p = np.asarray(positions, dtype=np.float64)[key_arr[:, 0] - 1]
    uv = None
    if texcoords:
        if key_arr[:, 1].max() > len(texcoords):
            raise SceneError(f"{err}: {path}: reference to an invalid texture coordinate")
        t = np.vstack([np.zeros((1, 2)), np.asarray(texcoords, dtype=np.float64)])
        uv = t[key_arr[:, 1]]
        if flip_tex_coords:
            uv[:, 1] = 1.0 - uv[:, 1]
    elif key_arr[:, 1].max() > 0:
        raise SceneError(f"{err}: {path}: reference to an invalid texture coordinate")
    n = None
    if normals:
        if key_arr[:, 2].max() > len(normals):
            raise SceneError(f"{err}: {path}: reference to an invalid vertex normal")
        if key_arr[:, 2].min() == 0:
            raise SceneError(f"{err}: {path}: some face vertices have normals and some "
                             f"do not")
        n = np.asarray(normals, dtype=np.float64)[key_arr[:, 2] - 1]
    elif key_arr[:, 2].max() > 0:
        raise SceneError(f"{err}: {path}: reference to an invalid vertex normal")
    return p, np.asarray(tris, dtype=np.uint32), n, uv


def _read_ply(path, err, quote=True):
    """PLY (ascii or binary) through plyfile; Mitsuba's names: x y z, nx ny nz,
    u v | texture_u texture_v | s t, face list vertex_indices | vertex_index.
    Faces must be triangles (Mitsuba 3.9.1 rejects other polygons). The
    other properties of vertices and faces become Mitsuba's mesh attributes
    (_ply_attributes); other elements are ignored. Returns positions,
    faces, normals, uvs and the attributes."""
    try:
        from plyfile import PlyData
    except ImportError:  # pragma: no cover - plyfile is a declared dependency
        raise SceneError(f"{err}: loading PLY files needs the 'plyfile' package") from None
    try:
        ply = PlyData.read(path)
    except Exception as e:  # plyfile raises several exception types
        # Its messages may quote the header; an untrusted scene's gets the type only.
        why = _quote(e, 200) if quote else type(e).__name__
        raise SceneError(f"{err}: {path}: cannot read PLY file ({why})") from None
    names = [el.name for el in ply.elements]
    if "vertex" not in names or "face" not in names:
        raise SceneError(f"{err}: {path}: PLY file needs 'vertex' and 'face' elements")
    vert, face = ply["vertex"], ply["face"]
    props = {pr.name for pr in vert.properties}
    if not {"x", "y", "z"} <= props:
        raise SceneError(f"{err}: {path}: PLY vertices need x, y, z")
    p = np.stack([np.asarray(vert[c], dtype=np.float64) for c in "xyz"], axis=1)
    n = None
    if {"nx", "ny", "nz"} <= props:
        n = np.stack([np.asarray(vert[c], dtype=np.float64) for c in ("nx", "ny", "nz")], axis=1)
    uv = None
    for us, vs in (("u", "v"), ("texture_u", "texture_v"), ("s", "t")):
        if {us, vs} <= props:
            uv = np.stack([np.asarray(vert[us], dtype=np.float64),
                           np.asarray(vert[vs], dtype=np.float64)], axis=1)
            break
    fprops = {pr.name for pr in face.properties}
    field = ("vertex_indices" if "vertex_indices" in fprops
             else "vertex_index" if "vertex_index" in fprops else None)
    if field is None:
        raise SceneError(f"{err}: {path}: PLY faces need a vertex_indices list")
    lists = face[field]
    if len(lists) == 0:
        raise SceneError(f"{err}: {path}: the PLY file has no faces")
    if any(len(x) != 3 for x in lists):
        raise SceneError(f"{err}: {path}: PLY faces must be triangles (as in Mitsuba 3)")
    f = np.array(np.vstack(lists), dtype=np.int64)
    if f.min() < 0 or f.max() >= len(p):
        raise SceneError(f"{err}: {path}: face index out of range")
    if not all(a is None or np.all(np.isfinite(a)) for a in (p, n, uv)):
        raise SceneError(f"{err}: {path}: non-finite vertex data")
    attributes = {**_ply_attributes(vert, "vertex_", {"x", "y", "z", "nx", "ny", "nz", "u", "v", "texture_u",
                                                       "texture_v", "s", "t"}),
                  **_ply_attributes(face, "face_", {field})}
    for name, a in attributes.items():
        if not np.all(np.isfinite(a)):
            raise SceneError(f"{err}: {path}: non-finite values in attribute '{name}'")
    return p, f.astype(np.uint32), n, uv, attributes


def _ply_attributes(element, prefix, taken):
    """An element's other scalar properties as Mitsuba 3's PLY reader groups
    them into mesh attributes (src/shapes/ply.cpp): NAME_0, NAME_1, ...
    become attribute prefix + NAME with one channel each; r, g, b (or red,
    green, blue) become prefix + "color", integers kept as they are
    (Mitsuba 3.9.1 warns that colours should lie in [0, 1] and keeps 255;
    measured with mitsuba.load_dict). Only groups of 1 or 3 channels are
    kept (mesh_attribute reads no other)."""
    groups = {}
    for pr in element.properties:
        name = pr.name
        if name in taken or not hasattr(pr, "val_dtype") or hasattr(pr, "len_dtype"):
            continue
        head, _, tail = name.rpartition("_")
        if head and tail.isdigit():
            groups.setdefault(head, {})[int(tail)] = name
        elif name in ("r", "g", "b", "red", "green", "blue"):
            groups.setdefault("color", {})["rgb".index(name[0])] = name
    out = {}
    for head, chans in groups.items():
        if sorted(chans) not in ([0], [0, 1, 2]):
            continue
        cols = []
        for k in sorted(chans):
            cols.append(np.asarray(element[chans[k]], dtype=np.float64))
        out[prefix + head] = np.stack(cols, axis=1).astype(np.float32)
    return out


def _mesh_shape(shape, m, p, f, n, uv, face_normals, err):
    """Fill a mesh ShapeDesc in world space (float64 maths, float32 storage);
    `err` prefixes errors."""
    shape.type = "mesh"
    shape.positions = np.ascontiguousarray(_apply_points(m, p, err))
    shape.indices = np.ascontiguousarray(f.astype(np.uint32).reshape(-1, 3))
    if face_normals:
        shape.normals = None
    elif n is not None:
        shape.normals = np.ascontiguousarray(_apply_normals(m, n))
    else:
        shape.normals = _vertex_normals(shape.positions, shape.indices)
    shape.uvs = None if uv is None else np.ascontiguousarray(uv.astype(np.float32))


def _rectangle_mesh():
    """Mitsuba's rectangle: [-1,1]^2 at z = 0, normal +z (the winding below),
    uv = ((x+1)/2, (y+1)/2). Mitsuba 3 intersects it analytically with the
    normal cross(dp/du, dp/dv), which is what this winding gives, mirrors
    included."""
    p = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float64)
    uv = (p[:, :2] + 1.0) * 0.5
    f = np.array([[0, 1, 2], [2, 3, 0]], dtype=np.uint32)
    return p, f, uv


# Mitsuba's cube: per face its outward normal and its four corners, with uvs
# (0,1) (1,1) (1,0) (0,0) and triangles (0,1,2) (3,0,2), in Mitsuba's order
# (-y, +y, +x, +z, -x, -z) so that vertex and face ids agree with Mitsuba's.
_CUBE_FACES = (
    ((0, -1, 0), ((1, -1, -1), (1, -1, 1), (-1, -1, 1), (-1, -1, -1))),
    ((0, 1, 0), ((1, 1, -1), (-1, 1, -1), (-1, 1, 1), (1, 1, 1))),
    ((1, 0, 0), ((1, -1, -1), (1, 1, -1), (1, 1, 1), (1, -1, 1))),
    ((0, 0, 1), ((1, -1, 1), (1, 1, 1), (-1, 1, 1), (-1, -1, 1))),
    ((-1, 0, 0), ((-1, -1, 1), (-1, 1, 1), (-1, 1, -1), (-1, -1, -1))),
    ((0, 0, -1), ((1, 1, -1), (1, -1, -1), (-1, -1, -1), (-1, 1, -1))),
)


def _cube_mesh():
    p = np.array([c for _, cs in _CUBE_FACES for c in cs], dtype=np.float64)
    n = np.array([nn for nn, _ in _CUBE_FACES for _ in range(4)], dtype=np.float64)
    uv = np.tile(np.array([[0, 1], [1, 1], [1, 0], [0, 0]], dtype=np.float64), (6, 1))
    f = np.array([[4 * i, 4 * i + 1, 4 * i + 2] for i in range(6)]
                 + [[4 * i + 3, 4 * i, 4 * i + 2] for i in range(6)], dtype=np.uint32)
    # Mitsuba interleaves the two triangles of each face.
    f = f.reshape(2, 6, 3).transpose(1, 0, 2).reshape(-1, 3)
    return p, f, n, uv


# Mitsuba's serialized mesh format (Mitsuba 3 src/shapes/serialized.cpp, its
# documentation "Format description"): little endian; per mesh a uint16
# 0x041C, a uint16 version (3 or 4), then a zlib stream with uint32 flags,
# (version 4) a NUL-terminated name, uint64 vertex and triangle counts, the
# positions, then normals, texture coordinates and colours where the flags
# say so (float32, or float64 with flag 0x2000), then uint32 triangle
# indices (uint64 beyond 2^32 vertices). The file ends with each mesh's
# offset (uint64 in version 4, uint32 in version 3) and a uint32 count.
# Read here with Python's zlib and numpy: no maintained Python package reads
# this format, and the layout is a few lines.
_SER_MAGIC = 0x041C
_SER_NORMALS, _SER_TEXCOORDS, _SER_COLORS = 0x0001, 0x0002, 0x0008
_SER_DOUBLE = 0x2000


def _read_serialized(path, shape_index, err, quote=True):
    """(positions, faces, normals or None, uvs or None) of mesh number
    `shape_index` of a .serialized file. The face-normals flag (0x0010) is
    read past: Mitsuba 3's reader ignores it too (its documentation calls it
    face_normals = true; measured with mitsuba.load_dict, 3.9.1: the file's
    vertex normals are kept)."""
    import struct
    import zlib

    name = _quote(path) if quote else "the file"
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as e:
        raise SceneError(f"{err}: cannot read serialized mesh {name} ({e.strerror})") from None

    def bad(why):
        return SceneError(f"{err}: {name}: not a valid Mitsuba serialized mesh ({why})")

    if len(data) < 8:
        raise bad("too short")
    magic, version = struct.unpack_from("<HH", data, 0)
    if magic != _SER_MAGIC:
        raise bad(f"format identifier 0x{magic:04X}, expected 0x041C")
    if version not in (3, 4):
        raise bad(f"version {version}, expected 3 or 4")
    count = struct.unpack_from("<I", data, len(data) - 4)[0]
    if shape_index >= max(count, 1):
        raise SceneError(f"{err}: shape_index {shape_index} is out of range: {name} holds {count} mesh"
                         f"{'es' if count != 1 else ''} (0 .. {count - 1})")
    offset = 0
    if shape_index > 0:
        size = 8 if version == 4 else 4
        at = len(data) - 4 - size * (count - shape_index)
        if at < 0:
            raise bad("truncated offset table")
        offset = struct.unpack_from("<Q" if version == 4 else "<I", data, at)[0]
        if offset + 4 > len(data) or struct.unpack_from("<H", data, offset)[0] != _SER_MAGIC:
            raise bad(f"mesh {shape_index} does not start at offset {offset}")
    try:
        raw = zlib.decompressobj().decompress(data[offset + 4:])
    except zlib.error as e:
        raise bad(f"zlib: {e}") from None
    pos = 0

    def take(nbytes):
        nonlocal pos
        if pos + nbytes > len(raw):
            raise bad("the compressed stream ends early")
        out = raw[pos:pos + nbytes]
        pos += nbytes
        return out

    flags = struct.unpack("<I", take(4))[0]
    if version == 4:
        end = raw.find(b"\0", pos)
        if end < 0:
            raise bad("unterminated mesh name")
        pos = end + 1
    nv, nf = struct.unpack("<QQ", take(16))
    if nv == 0 or nf == 0:
        raise bad(f"{nv} vertices and {nf} triangles")
    real = np.dtype("<f8") if flags & _SER_DOUBLE else np.dtype("<f4")

    def array(dim):
        return np.frombuffer(take(int(nv) * dim * real.itemsize), real).reshape(-1, dim).astype(np.float64)

    p = array(3)
    n = array(3) if flags & _SER_NORMALS else None
    uv = array(2) if flags & _SER_TEXCOORDS else None
    if flags & _SER_COLORS:
        array(3)  # vertex colours: read past (Mitsuba does not use them either)
    index = np.dtype("<u8") if nv > 0xFFFFFFFF else np.dtype("<u4")
    f = np.frombuffer(take(int(nf) * 3 * index.itemsize), index).reshape(-1, 3)
    if f.max() >= nv:
        raise bad(f"a triangle names vertex {int(f.max())} of {nv}")
    if not (np.all(np.isfinite(p)) and (n is None or np.all(np.isfinite(n)))
            and (uv is None or np.all(np.isfinite(uv)))):
        raise bad("non-finite vertex data")
    return p, f.astype(np.uint32), n, uv
