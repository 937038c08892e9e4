# SPDX-License-Identifier: GPL-3.0-or-later
"""A family of hard mirrors nothing in the project was tuned on (issue 44, item 5), numpy only.

Twelve mirrors in two halves: a *tuning* half, which may guide changes, and a *held-out*
half, measured only (``tests/benchmarks/bench_held_out_family.py`` reports them apart).
Each member is a list of :class:`Part`: mirrors (meshes with their normals, or a
metaball of CAPSULE elements, which only Blender can mesh) and diffuse obstacles placed
close to them. Coordinates are relative to the member's centre; the benchmark puts it on
the bumpy-ball demo's stage.

Tuning: a star-shaped bumpy ball (bumps 12 % of the radius, lobes (5, 4)); a sphere with
three smooth dents 15 % deep; a torus (1, 0.35) tilted 60 degrees; the demo's teapot; a
unit ball with a cube 2 % of its radius from its surface; two balls facing each other.

Held-out: a bumpy ball (18 %, lobes (3, 6)); a hammered sphere (36 random dents 4-6 %
deep); fused capsules (a balloon-animal metaball); a car-body-like shell (a squashed
superellipsoid with a belt-line crease, its normals split along it as Blender's Edge
Split modifier splits them); a vertical cylinder 4 % of the radius from a bumpy (10 %)
ball; a bumpy ball facing a tilted ellipsoid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..engine.geometry import shapes
from ..engine.geometry.sphere import bumpy_icosphere, icosphere
from ..engine.scene import vertex_normals
from . import surfaces

#: Geodesic subdivisions of the spheres (10,242 vertices, 20,480 triangles).
SUBDIVISIONS = 5
TUNING = ("star_ball", "dented_sphere", "torus", "teapot", "ball_cube_contact", "two_balls")
HELD_OUT = ("bumpy_ball_3_6", "hammered_sphere", "balloon_capsules", "car_shell", "bumpy_cylinder_contact",
            "bumpy_and_ellipsoid")
#: The stage's floor below the member's centre (the demo ball's centre is 1.1 above it).
FLOOR_BELOW = 1.1


@dataclass(frozen=True)
class Capsule:
    """One CAPSULE metaball element: a segment of half length ``half_length`` along the
    unit ``direction`` through ``centre``, thickened by ``radius`` (Blender's element radius)."""

    centre: tuple
    direction: tuple
    half_length: float
    radius: float

    def ends(self) -> np.ndarray:
        centre, direction = np.asarray(self.centre, float), np.asarray(self.direction, float)
        return np.stack([centre - self.half_length * direction, centre + self.half_length * direction])


@dataclass(frozen=True)
class Part:
    """One object of a member: a mirror mesh (``shape``), a mirror metaball (``capsules``)
    or a diffuse obstacle (``mirror`` False)."""

    name: str
    mirror: bool
    shape: shapes.Shape | None = None
    capsules: tuple = ()


def _shape(vertices, triangles, normals=None) -> shapes.Shape:
    """A triangle Shape; normals from the faces (area-weighted) where none are given."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    normals = vertex_normals(vertices, triangles) if normals is None else np.asarray(normals, dtype=np.float64)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    return shapes.Shape(vertices, normals, tris=triangles)


def _rotation(axis, degrees: float) -> np.ndarray:
    """3x3 rotation by ``degrees`` about the unit ``axis`` (Rodrigues)."""
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    angle = math.radians(degrees)
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * k @ k


def _turned(shape: shapes.Shape, rotation: np.ndarray, offset=(0.0, 0.0, 0.0)) -> shapes.Shape:
    return shapes.Shape(shape.vertices @ rotation.T + np.asarray(offset, float), shape.normals @ rotation.T,
                        shape.tris, shape.quads)


def sphere(radius: float = 1.0, centre=(0.0, 0.0, 0.0), subdivisions: int = SUBDIVISIONS) -> shapes.Shape:
    """A geodesic sphere with its exact (radial) normals."""
    ball = icosphere(centre, radius, subdivisions)
    return _shape(ball.vertices, ball.triangles, ball.normals)


def bumpy_ball(amplitude: float, lobes=(5, 4), radius: float = 1.0, centre=(0.0, 0.0, 0.0),
               subdivisions: int = SUBDIVISIONS) -> shapes.Shape:
    """Radius ``radius`` (1 + amplitude sin(m phi) sin(n theta)): star-shaped, not convex
    (``engine/geometry/sphere.py``'s bumpy icosphere), normals from the faces."""
    ball = bumpy_icosphere(centre, radius, subdivisions, amplitude, tuple(lobes))
    return _shape(ball.vertices, ball.triangles, ball.normals)


def unit_directions(azimuth_elevation_degrees) -> np.ndarray:
    """(K, 3) unit vectors from (azimuth, elevation) pairs in degrees (azimuth from +X toward +Y)."""
    a, e = np.radians(np.asarray(azimuth_elevation_degrees, dtype=np.float64)).T
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=1)


def dent_scale(directions: np.ndarray, centres: np.ndarray, depths, width: float) -> np.ndarray:
    """(N,) radial scale 1 - sum_k depth_k exp(-theta_k^2 / (2 width^2)) of unit
    ``directions``, theta_k the angle to dent k's centre: smooth round dents."""
    theta = np.arccos(np.clip(directions @ np.asarray(centres).T, -1.0, 1.0))
    return 1.0 - (np.asarray(depths) * np.exp(-0.5 * (theta / width) ** 2)).sum(axis=1)


#: The dented sphere's three dents: centres (azimuth, elevation), depth, angular width (radians).
DENTS = ((-90.0, 10.0), (-30.0, 40.0), (-150.0, -20.0))
DENT_DEPTH, DENT_WIDTH = 0.15, 0.3


def dented_sphere(subdivisions: int = SUBDIVISIONS) -> shapes.Shape:
    """A unit sphere with three smooth dents :data:`DENT_DEPTH` deep (the dents are over a
    radian apart: each one's depth is its own to 0.1 %)."""
    d = icosphere((0.0, 0.0, 0.0), 1.0, subdivisions)
    scale = dent_scale(d.normals, unit_directions(DENTS), [DENT_DEPTH] * len(DENTS), DENT_WIDTH)
    return _shape(d.normals * scale[:, None], d.triangles)


HAMMER_DENTS, HAMMER_DEPTHS, HAMMER_WIDTH, HAMMER_SEPARATION, HAMMER_SEED = 36, (0.04, 0.06), 0.09, 0.4, 44


def hammer_dents(count: int = HAMMER_DENTS, seed: int = HAMMER_SEED) -> tuple[np.ndarray, np.ndarray]:
    """(centres (K, 3), depths (K,)): ``count`` random dent centres at least
    :data:`HAMMER_SEPARATION` radians apart, depths uniform in :data:`HAMMER_DEPTHS`."""
    rng = np.random.default_rng(seed)
    centres = []
    while len(centres) < count:
        candidate = rng.normal(size=3)
        candidate /= np.linalg.norm(candidate)
        if all(float(candidate @ c) < math.cos(HAMMER_SEPARATION) for c in centres):
            centres.append(candidate)
    return np.array(centres), rng.uniform(*HAMMER_DEPTHS, size=count)


def hammered_sphere(subdivisions: int = SUBDIVISIONS) -> shapes.Shape:
    """A unit sphere with :data:`HAMMER_DENTS` small round dents (:func:`hammer_dents`)."""
    d = icosphere((0.0, 0.0, 0.0), 1.0, subdivisions)
    centres, depths = hammer_dents()
    return _shape(d.normals * dent_scale(d.normals, centres, depths, HAMMER_WIDTH)[:, None], d.triangles)


def torus(tilt_degrees: float = 60.0) -> shapes.Shape:
    """Major radius 1, minor 0.35 (``tools/surfaces.py``, exact normals), turned about X."""
    ring = surfaces.torus((0.0, 0.0, 0.0), 1.0, 0.35, 64, 24)
    return _turned(_shape(ring.vertices, ring.triangles, ring.normals), _rotation((1, 0, 0), tilt_degrees))


def teapot() -> shapes.Shape:
    """The demo's teapot (``engine/geometry/shapes.py``), its bounding box centred."""
    pot = shapes.teapot()
    lo, hi = pot.vertices.min(axis=0), pot.vertices.max(axis=0)
    return pot.moved(-0.5 * (lo + hi))


def superellipsoid_radius(directions: np.ndarray, radii, exponent: float) -> np.ndarray:
    """(N,) distance from the centre along unit ``directions`` to |x/a|^p + |y/b|^p + |z/c|^p = 1."""
    return (np.abs(directions / np.asarray(radii, float)) ** exponent).sum(axis=1) ** (-1.0 / exponent)


#: The car shell: superellipsoid radii (2 : 1 : 0.6), exponent, and its belt-line crease
#: (polar angle from +Z, ridge height as a share of the radius, half width in radians).
CAR_RADII, CAR_EXPONENT = (1.3, 0.65, 0.39), 3.0
CREASE_POLAR, CREASE_HEIGHT, CREASE_WIDTH = math.radians(75.0), 0.06, 0.35


def crease_scale(polar: np.ndarray) -> np.ndarray:
    """Radial scale of the belt-line ridge: 1 + h (1 - |t|)^2, t = (polar - crease) / width
    (|t| < 1): continuous, with a sharp crease at t = 0 and smooth where it ends."""
    t = np.abs(np.asarray(polar, float) - CREASE_POLAR) / CREASE_WIDTH
    return 1.0 + CREASE_HEIGHT * np.clip(1.0 - t, 0.0, None) ** 2


def car_shell(segments: int = 128, rings_above: int = 32, rings_below: int = 40) -> shapes.Shape:
    """A car-body-like shell: the superellipsoid :data:`CAR_RADII` (exponent
    :data:`CAR_EXPONENT`) on a latitude-longitude grid, with a ridge whose crease runs
    around it at the polar angle :data:`CREASE_POLAR`. The crease's ring of vertices is
    there twice, one copy in the faces above and one in those below, so each side's
    smooth normals stop at it: what Blender's Edge Split modifier makes of a sharp edge
    (the mesh is closed but for that seam, whose two sides coincide)."""
    above = np.linspace(0.0, CREASE_POLAR, rings_above + 1)[1:]  # the last ring is the crease
    below = np.linspace(CREASE_POLAR, math.pi, rings_below + 1)[:-1]  # the first ring is the crease again
    polar = np.concatenate([above, below])
    azimuth = 2.0 * math.pi * np.arange(segments) / segments
    p, a = np.meshgrid(polar, azimuth, indexing="ij")
    ring_directions = np.stack([np.sin(p) * np.cos(a), np.sin(p) * np.sin(a), np.cos(p)], axis=-1).reshape(-1, 3)
    directions = np.concatenate([[[0.0, 0.0, 1.0]], ring_directions, [[0.0, 0.0, -1.0]]])
    polar_all = np.concatenate([[0.0], p.ravel(), [math.pi]])
    vertices = directions * (superellipsoid_radius(directions, CAR_RADII, CAR_EXPONENT)
                             * crease_scale(polar_all))[:, None]
    top, bottom = 0, len(vertices) - 1

    def ring(k):
        return 1 + k * segments + np.arange(segments)

    triangles = []
    nxt = np.roll(np.arange(segments), -1)
    triangles.append(np.stack([np.full(segments, top), ring(0), ring(0)[nxt]], axis=1))
    last = len(polar) - 1
    triangles.append(np.stack([np.full(segments, bottom), ring(last)[nxt], ring(last)], axis=1))
    for k in range(last):
        if k == rings_above - 1:
            continue  # the crease: the rings above and below it are not joined (the seam)
        r0, r1 = ring(k), ring(k + 1)
        triangles.append(np.stack([r0, r1, r1[nxt]], axis=1))
        triangles.append(np.stack([r0, r1[nxt], r0[nxt]], axis=1))
    triangles = np.concatenate(triangles)
    shape = _shape(vertices, triangles)
    if float(np.einsum("ij,ij->", shape.normals, vertices)) < 0.0:  # wound inward: turn every face
        shape = _shape(vertices, triangles[:, ::-1])
    return shape


def crease_rings(segments: int = 128, rings_above: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Vertex indices of :func:`car_shell`'s crease ring: the copy above, the copy below."""
    above = 1 + (rings_above - 1) * segments + np.arange(segments)
    return above, above + segments


def contact_cube(gap: float, size: float = 0.4, azimuth_degrees: float = -60.0) -> shapes.Shape:
    """A cube of side ``size`` beside the unit sphere about the origin, a face toward it
    ``gap`` from its surface (the face's centre is its nearest point)."""
    rotation = _rotation((0, 0, 1), azimuth_degrees)
    direction = rotation @ np.array([1.0, 0.0, 0.0])
    return _turned(shapes.box((size, size, size)), rotation, direction * (1.0 + gap + 0.5 * size))


def cylinder_axis_distance(ball: shapes.Shape, gap: float, radius: float, azimuth_degrees: float) -> float:
    """The distance from the centre at which a vertical cylinder of ``radius`` in the
    direction ``azimuth_degrees`` keeps ``gap`` from ``ball``'s vertices."""
    direction = unit_directions([(azimuth_degrees, 0.0)])[0][:2]
    xy = ball.vertices[:, :2]
    distance = 1.0
    for _ in range(60):  # the gap grows with the distance at a slope of about 1: a fixed point
        found = float(np.linalg.norm(xy - distance * direction, axis=1).min()) - radius
        distance += gap - found
        if abs(gap - found) < 1e-9:
            break
    return distance


def contact_cylinder(ball: shapes.Shape, gap: float, radius: float = 0.12, height: float = 2.4,
                     azimuth_degrees: float = -55.0, segments: int = 64) -> shapes.Shape:
    """A vertical cylinder standing on the stage's floor (:data:`FLOOR_BELOW` under the
    centre), ``gap`` from ``ball``'s vertices at its nearest."""
    distance = cylinder_axis_distance(ball, gap, radius, azimuth_degrees)
    axis = distance * unit_directions([(azimuth_degrees, 0.0)])[0]
    return shapes.cylinder(radius, height, segments).moved((axis[0], axis[1], -FLOOR_BELOW))


#: The balloon animal: body, neck, head, front and back legs (centre, direction, half length, radius).
BALLOON = (
    Capsule((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.45, 0.42),
    Capsule((0.55, 0.0, 0.38), (0.45, 0.0, 0.89), 0.22, 0.34),
    Capsule((0.78, 0.0, 0.78), (0.94, 0.0, 0.34), 0.18, 0.36),
    Capsule((0.42, 0.12, -0.5), (0.1, 0.2, 0.97), 0.22, 0.3),
    Capsule((-0.45, -0.1, -0.5), (-0.2, -0.15, 0.97), 0.22, 0.3),
)


def balloon_capsules() -> tuple:
    """:data:`BALLOON` with unit directions."""
    return tuple(Capsule(c.centre, tuple(np.asarray(c.direction) / np.linalg.norm(c.direction)), c.half_length,
                         c.radius) for c in BALLOON)


def segment_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Shortest distance between the segments ``a`` (2, 3) and ``b`` (2, 3) (sampled finely)."""
    t = np.linspace(0.0, 1.0, 201)[:, None]
    p, q = a[0] + t * (a[1] - a[0]), b[0] + t * (b[1] - b[0])
    return float(np.linalg.norm(p[:, None] - q[None], axis=2).min())


def member(name: str) -> list:
    """The parts of the family member ``name`` (one of :data:`TUNING` or :data:`HELD_OUT`)."""
    if name == "star_ball":
        return [Part("StarBall", True, bumpy_ball(0.12, (5, 4)))]
    if name == "dented_sphere":
        return [Part("DentedSphere", True, dented_sphere())]
    if name == "torus":
        return [Part("Torus", True, torus())]
    if name == "teapot":
        return [Part("Teapot", True, teapot())]
    if name == "ball_cube_contact":
        return [Part("Ball", True, sphere()), Part("ContactCube", False, contact_cube(0.02))]
    if name == "two_balls":
        return [Part("BallLeft", True, sphere(0.6, (-0.8, 0.0, 0.0))),
                Part("BallRight", True, sphere(0.6, (0.8, 0.0, 0.0)))]
    if name == "bumpy_ball_3_6":
        return [Part("BumpyBall", True, bumpy_ball(0.18, (3, 6)))]
    if name == "hammered_sphere":
        return [Part("HammeredSphere", True, hammered_sphere())]
    if name == "balloon_capsules":
        return [Part("Balloon", True, capsules=balloon_capsules())]
    if name == "car_shell":
        return [Part("CarShell", True, car_shell())]
    if name == "bumpy_cylinder_contact":
        ball = bumpy_ball(0.10, (4, 3))
        return [Part("BumpyBall", True, ball), Part("ContactCylinder", False, contact_cylinder(ball, 0.04))]
    if name == "bumpy_and_ellipsoid":
        egg = surfaces.ellipsoid((0.0, 0.0, 0.0), (0.4, 0.6, 0.75), SUBDIVISIONS)
        egg_shape = _turned(_shape(egg.vertices, egg.triangles, egg.normals), _rotation((0, 1, 0), 30.0),
                            (0.8, 0.0, 0.0))
        return [Part("BumpyBall", True, bumpy_ball(0.10, (6, 3), 0.6, (-0.8, 0.0, 0.0))),
                Part("Ellipsoid", True, egg_shape)]
    raise ValueError(f"unknown family member {name!r}; choose from {TUNING + HELD_OUT}")


def half_of(name: str) -> str:
    """"tuning" or "held-out"."""
    if name in TUNING:
        return "tuning"
    if name in HELD_OUT:
        return "held-out"
    raise ValueError(name)


def mirror_bounds(parts) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the mirror parts (a capsule's segment grown by its radius)."""
    points = []
    for part in parts:
        if not part.mirror:
            continue
        if part.shape is not None:
            points.append(part.shape.vertices)
        for capsule in part.capsules:
            points.append(capsule.ends() + capsule.radius)
            points.append(capsule.ends() - capsule.radius)
    stacked = np.concatenate(points)
    return stacked.min(axis=0), stacked.max(axis=0)
