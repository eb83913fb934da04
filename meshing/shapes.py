"""Built-in closed shapes with exact volumes: triangle surfaces for any backend, OCC solids for gmsh.

Every shape is centred on the origin (the centre of its bounding box); lengths are in metres.
``parse_shape("box:1,0.1,0.1")`` reads the command-line form ``NAME:D1,D2,...``. The shapes: ``box``,
``sphere``, ``cylinder``, ``torus``, ``ellipsoid``, ``capsule`` (a cylinder with hemispherical ends)
and ``l_bracket`` (an L-shaped polygon extruded along z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from meshing.geometry import triangle_area_normals

if TYPE_CHECKING:
    import trimesh

__all__ = ["SHAPE_NAMES", "Shape", "box", "capsule", "cylinder", "ellipsoid", "l_bracket", "l_bracket_polygon",
           "parse_shape", "sphere", "torus"]


@dataclass(frozen=True)
class _ShapeKind:
    parameters: tuple  # names of the dimensions, in order
    volume: Callable  # dimensions -> exact volume [m^3]
    surface: Callable  # (dimensions, size) -> trimesh.Trimesh
    occ: Callable  # (gmsh.model.occ, dimensions) -> volume tag


@dataclass(frozen=True)
class Shape:
    """A built-in closed shape: its name, its dimensions and everything derived from them.

    Parameters
    ----------
    name : str
        one of :data:`SHAPE_NAMES`
    dimensions : tuple of float
        the shape's dimensions [m], in the order of ``parameters``

    Examples
    --------
    >>> shape = parse_shape("box:1,0.1,0.1")
    >>> shape.parameters, round(shape.volume, 12)
    (('lx', 'ly', 'lz'), 0.01)
    >>> shape.surface(size=0.05).is_watertight
    True
    """

    name: str
    dimensions: tuple

    def __post_init__(self):
        if self.name not in _KINDS:
            raise ValueError(f"unknown shape {self.name!r}; known shapes: {', '.join(SHAPE_NAMES)}")
        parameters = _KINDS[self.name].parameters
        dimensions = tuple(float(d) for d in self.dimensions)
        if len(dimensions) != len(parameters):
            raise ValueError(
                f"{self.name} takes {len(parameters)} dimension(s) ({', '.join(parameters)}), got {len(dimensions)}"
            )
        for parameter, value in zip(parameters, dimensions):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{self.name}: {parameter} = {value} is not a positive finite length")
        if self.name == "torus" and dimensions[1] >= dimensions[0]:
            raise ValueError(
                f"torus: minor radius r = {dimensions[1]} must be < major radius R = {dimensions[0]} "
                "(otherwise the torus intersects itself)"
            )
        if self.name == "l_bracket" and not dimensions[2] < min(dimensions[0], dimensions[1]):
            raise ValueError(
                f"l_bracket: thickness = {dimensions[2]} must be < both legs lx = {dimensions[0]} and "
                f"ly = {dimensions[1]} (otherwise it is a box, not an L)"
            )
        object.__setattr__(self, "dimensions", dimensions)

    @property
    def parameters(self) -> tuple:
        """Names of the dimensions, in order."""
        return _KINDS[self.name].parameters

    @property
    def volume(self) -> float:
        """Exact volume of the shape [m^3]."""
        return float(_KINDS[self.name].volume(*self.dimensions))

    @property
    def extent(self) -> float:
        """Largest extent of the shape's bounding box [m]."""
        low, high = self.bounds
        return float((high - low).max())

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float -- lower and upper corners of the exact bounding box [m]."""
        d = self.dimensions
        if self.name == "box":
            half = (d[0] / 2, d[1] / 2, d[2] / 2)
        elif self.name == "cylinder":
            half = (d[0], d[0], d[1] / 2)
        elif self.name == "torus":
            half = (d[0] + d[1], d[0] + d[1], d[1])
        elif self.name == "ellipsoid":
            half = d
        elif self.name == "capsule":
            half = (d[0], d[0], d[0] + d[1] / 2)
        elif self.name == "l_bracket":
            half = (d[0] / 2, d[1] / 2, d[3] / 2)
        else:
            half = (d[0],) * 3
        return np.array([[-h for h in half], list(half)], dtype=np.float64)

    def surface(self, *, size: float) -> trimesh.Trimesh:
        """A closed, outward-wound triangle surface of the shape with edges of about ``size``.

        Parameters
        ----------
        size : float
            target edge length [m]; vertices lie on the exact shape

        Returns
        -------
        trimesh.Trimesh
            watertight, outward normals
        """
        if not (math.isfinite(size) and size > 0):
            raise ValueError(f"size = {size} is not a positive finite length")
        mesh = _KINDS[self.name].surface(self.dimensions, float(size))
        if mesh.volume < 0:
            mesh.invert()
        return mesh

    def add_to_gmsh(self) -> int:
        """Add the shape as one OCC solid to the current gmsh model and synchronise; returns its volume tag."""
        import gmsh

        tag = _KINDS[self.name].occ(gmsh.model.occ, self.dimensions)
        gmsh.model.occ.synchronize()
        return tag

    def spec(self) -> str:
        """The command-line form, e.g. ``box:1,0.1,0.1``."""
        return f"{self.name}:" + ",".join(f"{d:g}" for d in self.dimensions)

    def __str__(self) -> str:
        return self.spec()


# ---------------------------------------------------------------------- triangle surfaces
def _grid(nu, nv):
    """Parameters (k, 2) in [0, 1]^2 and triangles (2 nu nv, 3) of an nu x nv grid of quads."""
    u, v = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    index = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    return np.stack([u.ravel(), v.ravel()], axis=1), np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _welded(parts):
    """One surface from (vertices, faces) parts of a convex shape whose shared borders coincide; wound outward."""
    import trimesh

    vertices = np.concatenate([v for v, _ in parts])
    offsets = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
    faces = np.concatenate([f + offset for (_, f), offset in zip(parts, offsets)])
    # The shapes welded here are convex and centred on the origin: outward means away from it.
    normals = triangle_area_normals(vertices, faces)
    inward = np.einsum("ij,ij->i", normals, vertices[faces].mean(axis=1)) < 0
    faces[inward] = faces[inward][:, ::-1]
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.merge_vertices()
    return mesh


def _box_surface(d, size):
    d = np.asarray(d)
    parts = []
    for axis in range(3):
        u_axis, v_axis = [a for a in range(3) if a != axis]
        (nu, nv) = (max(1, math.ceil(d[u_axis] / size)), max(1, math.ceil(d[v_axis] / size)))
        uv, faces = _grid(nu, nv)
        for side in (-0.5, 0.5):
            vertices = np.empty((len(uv), 3))
            vertices[:, axis] = side * d[axis]
            vertices[:, u_axis] = (uv[:, 0] - 0.5) * d[u_axis]
            vertices[:, v_axis] = (uv[:, 1] - 0.5) * d[v_axis]
            parts.append((vertices, faces))
    return _welded(parts)


def _icosphere(radius, size):
    import trimesh

    # An icosahedron inscribed in the unit sphere has edges of 1.0515; each subdivision halves them.
    subdivisions = max(0, math.ceil(math.log2(1.0515 * radius / size)))
    return trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)


def _sphere_surface(d, size):
    mesh = _icosphere(d[0], size)
    mesh.vertices *= d[0]
    return mesh


def _ellipsoid_surface(d, size):
    mesh = _icosphere(max(d), size)
    mesh.vertices *= np.asarray(d)
    return mesh


def _cylinder_surface(d, size):
    from scipy.spatial import Delaunay

    radius, length = d
    sections = max(8, math.ceil(2 * math.pi * radius / size))
    rings = max(1, math.ceil(length / size))
    uv, faces = _grid(sections, rings)
    theta = 2 * math.pi * uv[:, 0]
    side = np.stack([radius * np.cos(theta), radius * np.sin(theta), (uv[:, 1] - 0.5) * length], axis=1)
    parts = [(side, faces)]
    # Each cap: the rim points plus concentric rings inside, triangulated in 2D (the disc is convex).
    levels = np.arange(1, max(1, math.ceil(radius / size)))[::-1] / max(1, math.ceil(radius / size))
    disc = [np.zeros((1, 2))]
    for level in np.concatenate([[1.0], levels]):
        count = max(6, math.ceil(sections * level)) if level < 1 else sections
        phi = 2 * math.pi * np.arange(count) / count
        disc.append(radius * level * np.stack([np.cos(phi), np.sin(phi)], axis=1))
    disc = np.concatenate(disc)
    triangles = Delaunay(disc).simplices
    for z in (-length / 2, length / 2):
        parts.append((np.column_stack([disc, np.full(len(disc), z)]), triangles))
    return _welded(parts)


def _torus_surface(d, size):
    import trimesh

    major, minor = d
    return trimesh.creation.torus(
        major_radius=major,
        minor_radius=minor,
        major_sections=max(8, math.ceil(2 * math.pi * (major + minor) / size)),
        minor_sections=max(6, math.ceil(2 * math.pi * minor / size)),
    )


def _capsule_surface(d, size):
    import trimesh

    radius, length = d
    # The profile in the (radius, z) half-plane: a quarter circle, the straight side, a quarter circle;
    # revolved about z. Its end points lie on the axis (radius exactly 0), where revolve closes the poles.
    quarter = max(2, math.ceil(math.pi / 2 * radius / size))
    theta = np.linspace(-math.pi / 2, 0.0, quarter + 1)
    lower = np.stack([radius * np.cos(theta), radius * np.sin(theta) - length / 2], axis=1)
    lower[0, 0] = 0.0
    z = np.linspace(-length / 2, length / 2, max(1, math.ceil(length / size)) + 1)[1:-1]
    side = np.stack([np.full(len(z), radius), z], axis=1)
    profile = np.concatenate([lower, side, lower[::-1] * [1.0, -1.0]])
    return trimesh.creation.revolve(profile, sections=max(8, math.ceil(2 * math.pi * radius / size)))


def _l_bracket_surface(d, size):
    lx, ly, thickness, depth = d
    # The L is the union of three rectangles of the grid x in {x0, x1, x2}, y in {y0, y1, y2} (the
    # corner square and one rectangle per leg): every face of the extrusion is a product of these
    # intervals, each cut into the same number of divisions wherever it appears, so the welded patches
    # share their border vertices (a conforming surface without a 2D mesher).
    xs, ys, zs = (-lx / 2, -lx / 2 + thickness, lx / 2), (-ly / 2, -ly / 2 + thickness, ly / 2), (-depth / 2, depth / 2)

    def cut(low, high):
        return np.linspace(low, high, max(1, math.ceil((high - low) / size)) + 1)

    x = [cut(xs[0], xs[1]), cut(xs[1], xs[2])]
    y = [cut(ys[0], ys[1]), cut(ys[1], ys[2])]
    z = cut(*zs)
    cells = ((0, 0), (1, 0), (0, 1))  # (x interval, y interval) of the corner and the two legs
    parts = []
    for i, j in cells:  # the caps z = -depth/2 and z = +depth/2
        for level, outward in ((zs[0], -1.0), (zs[1], 1.0)):
            parts.append(_flat_patch(x[i], y[j], (0, 1, 2), level, (0.0, 0.0, outward)))
    walls = [  # (axis across the wall, its coordinate, outward sign, the interval along the wall)
        (1, ys[0], -1.0, x[0]), (1, ys[0], -1.0, x[1]),  # the outer side of the x leg, y = y0
        (0, xs[2], 1.0, y[0]),                            # the end of the x leg, x = x2
        (1, ys[1], 1.0, x[1]),                            # the inner side of the x leg, y = y1
        (0, xs[1], 1.0, y[1]),                            # the inner side of the y leg, x = x1
        (1, ys[2], 1.0, x[0]),                            # the end of the y leg, y = y2
        (0, xs[0], -1.0, y[0]), (0, xs[0], -1.0, y[1]),  # the outer side of the y leg, x = x0
    ]
    for axis, level, outward, along in walls:
        other = 1 - axis  # the in-plane axis along the wall
        normal = [0.0, 0.0, 0.0]
        normal[axis] = outward
        parts.append(_flat_patch(along, z, (other, 2, axis), level, normal))
    return _oriented_patches(parts)


def _flat_patch(u, v, axes, level, normal):
    """A grid of triangles on a plane: coordinates ``u`` along ``axes[0]``, ``v`` along ``axes[1]``, ``level``
    on ``axes[2]``; (vertices, faces, outward normal)."""
    uv, faces = _grid(len(u) - 1, len(v) - 1)
    vertices = np.empty((len(uv), 3))
    vertices[:, axes[0]] = np.interp(uv[:, 0], np.linspace(0, 1, len(u)), u)
    vertices[:, axes[1]] = np.interp(uv[:, 1], np.linspace(0, 1, len(v)), v)
    vertices[:, axes[2]] = level
    return vertices, faces, np.asarray(normal, dtype=np.float64)


def _oriented_patches(parts):
    """One surface from flat (vertices, faces, outward normal) patches whose shared borders coincide."""
    import trimesh

    oriented = []
    for vertices, faces, normal in parts:
        inward = triangle_area_normals(vertices, faces) @ normal < 0
        faces = faces.copy()
        faces[inward] = faces[inward][:, ::-1]
        oriented.append((vertices, faces))
    vertices = np.concatenate([v for v, _ in oriented])
    offsets = np.cumsum([0] + [len(v) for v, _ in oriented[:-1]])
    faces = np.concatenate([f + offset for (_, f), offset in zip(oriented, offsets)])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.merge_vertices()
    return mesh


# ---------------------------------------------------------------------- OCC solids
def _box_occ(occ, d):
    return occ.addBox(-d[0] / 2, -d[1] / 2, -d[2] / 2, d[0], d[1], d[2])


def _sphere_occ(occ, d):
    return occ.addSphere(0.0, 0.0, 0.0, d[0])


def _ellipsoid_occ(occ, d):
    tag = occ.addSphere(0.0, 0.0, 0.0, 1.0)
    occ.dilate([(3, tag)], 0.0, 0.0, 0.0, d[0], d[1], d[2])
    return tag


def _cylinder_occ(occ, d):
    return occ.addCylinder(0.0, 0.0, -d[1] / 2, 0.0, 0.0, d[1], d[0])


def _torus_occ(occ, d):
    return occ.addTorus(0.0, 0.0, 0.0, d[0], d[1])


def _capsule_occ(occ, d):
    radius, length = d
    cylinder = occ.addCylinder(0.0, 0.0, -length / 2, 0.0, 0.0, length, radius)
    ends = [occ.addSphere(0.0, 0.0, z, radius) for z in (-length / 2, length / 2)]
    fused, _ = occ.fuse([(3, cylinder)], [(3, tag) for tag in ends])
    return _single_volume(fused, "capsule")


def _l_bracket_occ(occ, d):
    lx, ly, thickness, depth = d
    return _extruded_polygon_occ(occ, l_bracket_polygon(lx, ly, thickness), -depth / 2, depth)


def _extruded_polygon_occ(occ, polygon, z0, depth):
    """A simple polygon (k, 2) in the plane z = ``z0``, extruded by ``depth`` along z; returns the volume tag."""
    points = [occ.addPoint(float(x), float(y), z0) for x, y in polygon]
    lines = [occ.addLine(points[i], points[(i + 1) % len(points)]) for i in range(len(points))]
    face = occ.addPlaneSurface([occ.addCurveLoop(lines)])
    extruded = occ.extrude([(2, face)], 0.0, 0.0, depth)
    return _single_volume([dim_tag for dim_tag in extruded if dim_tag[0] == 3], "extruded polygon")


def _single_volume(dim_tags, what):
    volumes = [tag for dim, tag in dim_tags if dim == 3]
    if len(volumes) != 1:
        raise ValueError(f"gmsh made {len(volumes)} volumes of the {what}, expected one")
    return volumes[0]


_KINDS = {
    "box": _ShapeKind(("lx", "ly", "lz"), lambda a, b, c: a * b * c, _box_surface, _box_occ),
    "sphere": _ShapeKind(("r",), lambda r: 4 / 3 * math.pi * r**3, _sphere_surface, _sphere_occ),
    "cylinder": _ShapeKind(("r", "length"), lambda r, h: math.pi * r**2 * h, _cylinder_surface, _cylinder_occ),
    "torus": _ShapeKind(("R", "r"), lambda R, r: 2 * math.pi**2 * R * r**2, _torus_surface, _torus_occ),
    "ellipsoid": _ShapeKind(("a", "b", "c"), lambda a, b, c: 4 / 3 * math.pi * a * b * c,
                            _ellipsoid_surface, _ellipsoid_occ),
    "capsule": _ShapeKind(("r", "length"), lambda r, h: math.pi * r**2 * (h + 4 / 3 * r),
                          _capsule_surface, _capsule_occ),
    "l_bracket": _ShapeKind(("lx", "ly", "thickness", "depth"), lambda a, b, t, c: t * (a + b - t) * c,
                            _l_bracket_surface, _l_bracket_occ),
}

#: Names of the built-in shapes.
SHAPE_NAMES = tuple(_KINDS)


def box(lx: float, ly: float, lz: float) -> Shape:
    """An axis-aligned box of edges ``lx, ly, lz`` [m], centred on the origin."""
    return Shape("box", (lx, ly, lz))


def sphere(r: float) -> Shape:
    """A sphere of radius ``r`` [m]."""
    return Shape("sphere", (r,))


def cylinder(r: float, length: float) -> Shape:
    """A cylinder of radius ``r`` [m] and ``length`` [m] along z."""
    return Shape("cylinder", (r, length))


def torus(R: float, r: float) -> Shape:  # noqa: N803 -- R and r are the usual names
    """A torus around z of major radius ``R`` [m] and minor (tube) radius ``r < R`` [m]."""
    return Shape("torus", (R, r))


def ellipsoid(a: float, b: float, c: float) -> Shape:
    """An ellipsoid of semi-axes ``a, b, c`` [m] along x, y, z."""
    return Shape("ellipsoid", (a, b, c))


def capsule(r: float, length: float) -> Shape:
    """A capsule along z: a cylinder of radius ``r`` [m] and ``length`` [m] closed by two hemispheres of
    radius ``r``; it spans ``length + 2 r`` along z (``length`` is the distance between the hemispheres'
    centres, as trimesh's ``creation.capsule`` ``height``)."""
    return Shape("capsule", (r, length))


def l_bracket(lx: float, ly: float, thickness: float, depth: float) -> Shape:
    """An L-shaped bracket: the polygon :func:`l_bracket_polygon` in the xy plane extruded by ``depth`` [m]
    along z.

    Its legs are ``lx`` [m] along x and ``ly`` [m] along y, both ``thickness`` [m] thick (< lx, ly), joined
    at the corner (-lx/2, -ly/2) of the bounding box; the x leg's end is the face x = lx/2, the y leg's
    the face y = ly/2.

    Examples
    --------
    >>> shape = l_bracket(0.4, 0.3, 0.05, 0.1)
    >>> round(shape.volume, 12)   # thickness (lx + ly - thickness) depth
    0.00325
    """
    return Shape("l_bracket", (lx, ly, thickness, depth))


def l_bracket_polygon(lx: float, ly: float, thickness: float) -> np.ndarray:
    """(6, 2) float -- the L's outline [m], counter-clockwise from the outer corner (-lx/2, -ly/2).

    Parameters
    ----------
    lx, ly : float
        the legs' lengths along x and y [m]
    thickness : float
        both legs' thickness [m], < lx and ly
    """
    x0, y0 = -lx / 2, -ly / 2
    return np.array([[x0, y0], [lx / 2, y0], [lx / 2, y0 + thickness], [x0 + thickness, y0 + thickness],
                     [x0 + thickness, ly / 2], [x0, ly / 2]], dtype=np.float64)


def parse_shape(spec: str) -> Shape:
    """Read a built-in shape from its command-line form ``NAME:D1,D2,...``.

    Parameters
    ----------
    spec : str
        ``NAME:D1,D2,...`` with NAME one of :data:`SHAPE_NAMES` and its dimensions [m] in order: ``box:lx,ly,lz``,
        ``sphere:r``, ``cylinder:r,length``, ``torus:R,r``, ``ellipsoid:a,b,c``, ``capsule:r,length`` (see
        :func:`capsule`), ``l_bracket:lx,ly,thickness,depth`` (see :func:`l_bracket`); e.g. ``"box:1,0.1,0.1"``,
        ``"torus:0.5,0.15"``, ``"capsule:0.1,0.4"``

    Raises
    ------
    ValueError
        For an unknown shape name, the wrong number of dimensions, or dimensions that are
        not positive finite numbers.

    Examples
    --------
    >>> parse_shape("torus:0.5,0.15")
    Shape(name='torus', dimensions=(0.5, 0.15))
    >>> parse_shape("l_bracket:0.4,0.3,0.05,0.1").parameters
    ('lx', 'ly', 'thickness', 'depth')
    """
    name, colon, rest = str(spec).strip().partition(":")
    name = name.strip().lower()
    if name not in _KINDS:
        raise ValueError(f"unknown shape {name!r} in {spec!r}; known shapes: {', '.join(SHAPE_NAMES)}")
    if not colon or not rest.strip():
        example = ",".join(_KINDS[name].parameters)
        raise ValueError(f"{spec!r} gives no dimensions; expected {name}:{example}")
    try:
        dimensions = tuple(float(part) for part in rest.split(","))
    except ValueError:
        raise ValueError(f"dimensions in {spec!r} must be numbers separated by commas") from None
    return Shape(name, dimensions)


def looks_like_shape(text: str) -> bool:
    """Whether ``text`` is meant as a built-in shape spec (``NAME:...`` with no path separator or extension)."""
    name, colon, _ = str(text).partition(":")
    return bool(colon) and name.isidentifier() and len(name) > 1
