"""Swept hexahedral meshes of the bellow joint and of the whole finger (z >= 0), for Q2.

The joint of :func:`fem.mesh.geometry.build_joint` is a union of axis-aligned boxes: in the x-y
profile every feature (caps, cells, valleys, pockets, channel, spine, walls) starts and
ends at one of a few coordinates, and along z the chambers run from the symmetry plane
z = 0 to the side wall z in [Z - t, Z]. With the breakpoints (mm; L length, t wall,
s spine, H = height/2, Hv = valley_height/2, Z = width/2, cells [c0_i, c1_i], pockets
[a_i, b_i] with a_0 = c0_0, b_last = c1_last and otherwise a_i = c0_i + t, b_i = c1_i - t)::

    x: 0, cap, a_i, b_i, c0_i, c1_i, L - cap, L
    y: -H, -(H - t), -Hv, -(Hv - t), -s/2, s/2, Hv - t, Hv, H - t, H
    z: 0, Z - t, Z

every box between neighbouring breakpoints is wholly solid, wholly chamber or wholly
outside (a valley gap y > Hv between two cells). The finger of
:func:`fem.mesh.geometry.build_finger` is the same kind of union: its parts lie along x from
x0_k = finger.rest_start(k), every joint the joint above of its own shape
(FingerGeometry.joint_at) shifted by x0_k, every rigid part the box [x0_k, x0_k + l_k] x
[-h_k/2, h_k/2] x [0, w_k/2]. Its breakpoints are every joint's own x breakpoints + x0_k
and every rigid part's ends along x, and along y and z the union of every joint's and
every rigid part's (+-h_k/2; 0, w_k/2): a swept mesh has one (y, z) grid, so joints of
different sections each carry the other's y and z lines too (the paper's joint and
soft4: y breakpoints 3.0 and 3.2 mm, a 0.2 mm layer through the whole finger), and the
bonds between parts of different sections stay conforming.

One tensor grid over those breakpoints (a :class:`Layout`): the mesh of ``divisions`` n
cuts every interval of length d into n * max(1, ceil(d / S0)) equal elements, S0 =
FingerGeometry.rigid_mesh_size for a finger (6 mm: the long rigid intervals get elements
of at most S0 / n) and infinite for a joint, except that a joint's ``hex_size`` S grades it:
its intervals take S0 = S (the long spans of the cells' walls and of the chambers along z
get more elements than the walls' thickness). A hexahedron is kept
when its midpoint lies in the solid (a joint's outer box less its chambers and valley
gaps, or a rigid box). So every joint wall is n elements thick, element sizes scale
exactly as 1/n, and the meshes of n = 1, 2, 3, ... (one S) are nested (the Richardson
family of fem.studies.mesh_study). A joint whose intervals are all shorter than S0 (the paper's:
at most 5.8 mm, the chambers' z extent Z - t; 4.69 mm along x) and whose y, z breakpoints
hold every other part's (rigid parts of its section, the other joints of its shape) is
meshed in the finger exactly as alone. The profile is polygonal, so straight-sided hexahedra represent the solid
exactly (volumes and areas to round-off).

The y breakpoints are symmetric (every box is centred on y = 0) and the grid is
symmetrised, so the node set is exactly its own y-mirror, node by node, as the
tetrahedral meshes are.

Tags follow from the exact geometry by midpoints. Joint (fem.mesh.geometry.TAGS): cells
``distal_cap`` beyond x = L - cap, else ``solid``; boundary facets ``proximal`` x = 0,
``distal`` x = L, ``symmetry`` z = 0, ``top_chamber`` / ``bottom_chamber`` the walls of the
closed chamber region at y > 0 / y < 0 (z > 0), ``valley_faces`` the outer cell faces
x = c1_i, c0_{i+1} with |y| > Hv. Finger (fem.mesh.geometry.finger_tags): cells ``part{k}``
(a rigid part, or a joint's body) and ``cap{k}`` (a joint's distal cap); facets
``top{k}`` / ``bottom{k}`` joint k's chamber walls, ``valley_faces`` of every joint,
``symmetry``, ``proximal`` x = 0 (the finger has no ``distal`` tag). The two faces of a
valley share their (y, z) grid, so every node has the exact partner that fem.physics.contact's
node-to-node pairs need.

Q2 on hexahedra needs quadrature degree 4 (3 x 3 x 3 Gauss points): degree 2 or 3 gives
2 x 2 x 2, which under-integrates the Q2 stiffness (hourglass modes); QUADRATURE is that
degree, and fem.mesh.discretisation uses it for every hexahedral discretisation.

Data flow: JointGeometry(divisions=n) or FingerGeometry(finger, JointGeometry(divisions=n))
-> fem.mesh.build.create_mesh -> create_hex_mesh / create_hex_finger_mesh -> layout -> hexahedra
-> fem.mesh.data.MeshData -> fem.physics.problem / fem.solvers.joint / fem.solvers.finger, exactly as the gmsh
tetrahedra.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from mpi4py import MPI

from fem.mesh.discretisation import HEX_QUADRATURE
from fem.mesh.geometry import TAGS, FingerGeometry, JointGeometry, finger_tags
from fem.mesh.data import MeshData

#: quadrature degree of Q2 hexahedra: 3 x 3 x 3 Gauss points (module docstring)
QUADRATURE = HEX_QUADRATURE
_TOL = 1e-6     # mm: coordinates closer than this are one breakpoint


# ---------------------------------------------------------------------- the joint's boxes
def pockets(geo: JointGeometry) -> list[tuple[float, float]]:
    """(a, b): x range (mm) of every cell's cavity, as fem.mesh.geometry's quarter cuts it."""
    cells, t = geo.cells(), geo.wall
    return [(c0 if i == 0 else c0 + t, c1 if i == len(cells) - 1 else c1 - t)
            for i, (c0, c1) in enumerate(cells)]


def breakpoints(geo: JointGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, z) breakpoints of the joint's boxes (mm, x from its proximal face), sorted
    (module docstring; the spine is one interval, so y = 0 is no breakpoint)."""
    L, t, s = geo.length, geo.wall, geo.spine
    H, Hv, Z = geo.height / 2, geo.valley_height / 2, geo.width / 2
    x = [0.0, geo.cap, L - geo.cap, L] + [c for cell in geo.cells() for c in cell]
    x += [c for pocket in pockets(geo) for c in pocket]
    y = [v for h in (s / 2, Hv - t, Hv, H - t, H) for v in (h, -h)]
    return _unique(x), _unique(y), _unique([0.0, Z - t, Z])


def in_chamber(geo: JointGeometry, x, y, z, closed: bool = False) -> np.ndarray:
    """Points (mm; arrays, x from the joint's proximal face) inside a chamber (either sign
    of y); with ``closed``, on its boundary too (up to 1e-6 mm)."""
    e = _TOL if closed else -_TOL
    t, s = geo.wall, geo.spine
    H, Hv, Z = geo.height / 2, geo.valley_height / 2, geo.width / 2
    ay = np.abs(y)

    def inside(v, lo, hi):
        return (v > lo - e) & (v < hi + e)

    chamber = inside(x, geo.cap, geo.length - geo.cap) & inside(ay, s / 2, Hv - t)
    for a, b in pockets(geo):
        chamber |= inside(x, a, b) & inside(ay, s / 2, H - t)
    return chamber & (z < Z - t + e)


def in_valley_gap(geo: JointGeometry, x, y) -> np.ndarray:
    """Points (mm, x from the proximal face) in the open gap of a valley, between two
    cells above |y| = Hv."""
    cells = geo.cells()
    gap = np.zeros(np.shape(x), dtype=bool)
    for (_, x1), (x2, _) in zip(cells[:-1], cells[1:]):
        gap |= (x > x1 + _TOL) & (x < x2 - _TOL)
    return gap & (np.abs(y) > geo.valley_height / 2 + _TOL)


def in_box(x, y, z, length: float, height: float, width: float) -> np.ndarray:
    """Points (mm) strictly inside the half box [0, length] x [-height/2, height/2] x
    [0, width/2] (z >= 0 taken for granted: the grid starts at z = 0)."""
    return (x > 0) & (x < length) & (np.abs(y) < height / 2) & (z < width / 2)


def in_joint(geo: JointGeometry, x, y, z) -> np.ndarray:
    """Points (mm, x from the proximal face) strictly inside the joint's solid: its outer
    box less its chambers and valley gaps."""
    box = in_box(x, y, z, geo.length, geo.height, geo.width)
    return box & ~in_chamber(geo, x, y, z) & ~in_valley_gap(geo, x, y)


def joint_facets(geo: JointGeometry, x, y, z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(top chamber, bottom chamber, valley face) masks of boundary-facet midpoints (mm,
    x from the joint's proximal face): the closed chamber region at z > 0 split by the
    sign of y, and the outer cell faces across a valley above |y| = Hv."""
    chamber = in_chamber(geo, x, y, z, closed=True) & (z > _TOL)
    valley = np.zeros(np.shape(x), dtype=bool)
    cells = geo.cells()
    for (_, x1), (x2, _) in zip(cells[:-1], cells[1:]):
        face = (np.abs(x - x1) < _TOL) | (np.abs(x - x2) < _TOL)
        valley |= face & (np.abs(y) > geo.valley_height / 2 + _TOL)
    return chamber & (y > 0), chamber & (y < 0), valley


# ---------------------------------------------------------------------- the tensor grid
@dataclass(frozen=True)
class Layout:
    """A solid made of axis-aligned boxes on one tensor grid (module docstring).

    ``breaks``: the (x, y, z) breakpoints (mm, sorted, y symmetric); ``max_size`` S0
    (mm) per axis, a number or one per interval: an interval of length d is cut into
    n * max(1, ceil(d / S0)) elements;
    ``solid(x, y, z)``: whether cell midpoints (mm, arrays) are in the solid;
    ``cell_tags(m)`` / ``facet_tags(m)``: the tag (0: none) of cells / boundary facets by
    their midpoints m (k, 3) mm."""

    breaks: tuple[np.ndarray, np.ndarray, np.ndarray]
    solid: Callable
    cell_tags: Callable
    facet_tags: Callable
    max_size: tuple = (math.inf, math.inf, math.inf)


def _unique(values) -> np.ndarray:
    v = np.sort(np.asarray(values, dtype=float))
    return v[np.concatenate([[True], np.diff(v) > _TOL])]


def interval_counts(breaks: np.ndarray, n: int, max_size=math.inf) -> np.ndarray:
    """Elements per interval of ``breaks``: n * max(1, ceil(d / max_size)), d (mm) the
    interval's length, max_size (mm) a number or one per interval."""
    return n * np.maximum(1, np.ceil(np.diff(breaks) / max_size - 1e-9)).astype(int)


def subdivide(breaks: np.ndarray, counts) -> np.ndarray:
    """Node coordinates (mm) of a 1D grid: interval i of ``breaks`` cut into counts[i]
    equal elements (an int: every interval alike); the breakpoints are kept exactly."""
    counts = np.broadcast_to(np.asarray(counts, dtype=int), (len(breaks) - 1,))
    inner = [a + (b - a) * np.arange(c) / c for a, b, c in zip(breaks[:-1], breaks[1:], counts)]
    return np.append(np.concatenate(inner), breaks[-1])


def grid(lay: Layout, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node coordinates (mm) along x, y and z of the tensor grid of ``n`` divisions; y is
    symmetrised, y_i = (y_i - y_{m-1-i}) / 2, so that y_{m-1-i} = -y_i exactly."""
    gx, gy, gz = (subdivide(b, interval_counts(b, n, s)) for b, s in zip(lay.breaks, lay.max_size))
    return gx, (gy - gy[::-1]) / 2, gz


def hexahedra(geometry: JointGeometry | FingerGeometry, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(points (p, 3) mm, cells (m, 8)) of the solid hexahedra of ``n`` divisions of a
    joint or a finger, vertices in DOLFINx order ((0,0,0), (1,0,0), (0,1,0), (1,1,0), then
    z = 1); unused grid nodes dropped."""
    lay = layout(geometry)
    gx, gy, gz = grid(lay, n)
    nx, ny = len(gx), len(gy)
    mid = [(g[:-1] + g[1:]) / 2 for g in (gx, gy, gz)]
    cx, cy, cz = np.meshgrid(*mid, indexing="ij")
    i, j, k = (a.ravel() for a in np.nonzero(lay.solid(cx, cy, cz)))

    def node(di, dj, dk):
        return (i + di) + nx * ((j + dj) + ny * (k + dk))

    cells = np.column_stack([node(di, dj, dk) for dk in (0, 1) for dj in (0, 1) for di in (0, 1)])
    used, cells = np.unique(cells, return_inverse=True)
    X, Y, Z = np.meshgrid(gx, gy, gz, indexing="ij")
    xyz = np.column_stack([a.ravel(order="F") for a in (X, Y, Z)])
    return xyz[used], cells.reshape(-1, 8).astype(np.int64)


def q2_nodes(geometry: JointGeometry | FingerGeometry) -> int:
    """Q2 node count of the mesh of ``geometry.divisions`` n (vertices, edge, face and
    cell midpoints): the vertices of the grid of 2n, whose extra lines are those midpoints."""
    return len(hexahedra(geometry, 2 * geometry.divisions)[0])


# ---------------------------------------------------------------------- the layouts
def layout(geometry: JointGeometry | FingerGeometry) -> Layout:
    """The Layout of a joint or of a finger."""
    return finger_layout(geometry) if isinstance(geometry, FingerGeometry) else joint_layout(geometry)


def joint_layout(geo: JointGeometry) -> Layout:
    """The joint alone: its breakpoints, its solid, TAGS (module docstring)."""
    def cell_tags(m):
        cap = m[:, 0] > geo.length - geo.cap
        return np.where(cap, TAGS["distal_cap"], TAGS["solid"]).astype(np.int32)

    def facet_tags(m):
        x, y, z = m.T
        tag = np.zeros(len(m), dtype=np.int32)
        top, bottom, valley = joint_facets(geo, x, y, z)
        tag[top], tag[bottom], tag[valley] = TAGS["top_chamber"], TAGS["bottom_chamber"], TAGS["valley_faces"]
        tag[np.abs(z) < _TOL] = TAGS["symmetry"]
        tag[np.abs(x) < _TOL] = TAGS["proximal"]
        tag[np.abs(x - geo.length) < _TOL] = TAGS["distal"]
        return tag

    S = geo.hex_size or math.inf
    return Layout(breakpoints(geo), lambda x, y, z: in_joint(geo, x, y, z), cell_tags, facet_tags, (S, S, S))


def part_spans(geo: FingerGeometry) -> list[tuple[float, float]]:
    """(x0, x1) of every part along the straight rest finger (mm)."""
    finger = geo.finger
    return [(finger.rest_start(k), finger.rest_start(k) + p.length) for k, p in enumerate(finger.parts)]


def joint_parts(geo: FingerGeometry) -> list[tuple[int, JointGeometry, float, float]]:
    """(part index k, its JointGeometry, x0, x1) of every joint part (mm, finger frame)."""
    spans = part_spans(geo)
    return [(k, geo.joint_at(k), *spans[k]) for k in geo.finger.joints]


def finger_breakpoints(geo: FingerGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, z) breakpoints of the finger (mm, finger frame; module docstring): along x
    every joint's own + its x0 and every rigid part's ends, along y and z the union of
    every part's."""
    x, y, z = [], [], []
    for k, (part, (x0, x1)) in enumerate(zip(geo.finger.parts, part_spans(geo))):
        if part.kind == "joint":
            bx, by, bz = breakpoints(geo.joint_at(k))
            x += list(bx + x0)
            y += list(by)
            z += list(bz)
        else:
            x += [x0, x1]
            y += [part.height / 2, -part.height / 2]
            z += [0.0, part.width / 2]
    return _unique(x), _unique(y), _unique(z)


def in_finger(geo: FingerGeometry, x, y, z) -> np.ndarray:
    """Points (mm, finger frame) strictly inside a part: a joint's solid (its own shape)
    or a rigid box."""
    solid = np.zeros(np.shape(x), dtype=bool)
    for k, (part, (x0, _)) in enumerate(zip(geo.finger.parts, part_spans(geo))):
        if part.kind == "joint":
            solid |= in_joint(geo.joint_at(k), x - x0, y, z)
        else:
            solid |= in_box(x - x0, y, z, part.length, part.height, part.width)
    return solid


def finger_layout(geo: FingerGeometry) -> Layout:
    """The finger: every part on one grid, fem.mesh.geometry.finger_tags (module docstring)."""
    tags, joints = finger_tags(geo.finger), joint_parts(geo)

    def cell_tags(m):
        x = m[:, 0]
        tag = np.zeros(len(m), dtype=np.int32)
        for k, (x0, x1) in enumerate(part_spans(geo)):
            tag[(x > x0) & (x < x1)] = tags[f"part{k}"]
        for k, jg, x0, x1 in joints:
            tag[(x > x1 - jg.cap) & (x < x1)] = tags[f"cap{k}"]
        return tag

    def facet_tags(m):
        x, y, z = m.T
        tag = np.zeros(len(m), dtype=np.int32)
        for k, jg, x0, _ in joints:
            top, bottom, valley = joint_facets(jg, x - x0, y, z)
            tag[top], tag[bottom], tag[valley] = tags[f"top{k}"], tags[f"bottom{k}"], tags["valley_faces"]
        tag[np.abs(z) < _TOL] = tags["symmetry"]
        tag[np.abs(x) < _TOL] = tags["proximal"]
        return tag

    bx, by, bz = breaks = finger_breakpoints(geo)
    rigid, joint = geo.rigid_mesh_size, min(geo.rigid_mesh_size, geo.joint.hex_size or math.inf)
    mid = (bx[:-1] + bx[1:]) / 2
    in_a_joint = np.zeros(len(mid), dtype=bool)
    for _, _, x0, x1 in joints:
        in_a_joint |= (mid > x0) & (mid < x1)
    return Layout(breaks, lambda x, y, z: in_finger(geo, x, y, z), cell_tags, facet_tags,
                  (np.where(in_a_joint, joint, rigid), joint, joint))


# ---------------------------------------------------------------------- DOLFINx
def _meshtags(mesh, dim: int, entities: np.ndarray, values: np.ndarray):
    from dolfinx.mesh import meshtags

    keep = values > 0
    order = np.argsort(entities[keep])
    return meshtags(mesh, dim, entities[keep][order].astype(np.int32), values[keep][order])


def _distributed(geometry: JointGeometry | FingerGeometry, n: int, comm: MPI.Comm):
    """The hexahedra of ``n`` divisions of ``geometry`` distributed over ``comm``
    (collective; rank 0 builds the cells), tagged by its layout: a fem.mesh.data.MeshData."""
    import ufl
    from dolfinx.mesh import compute_midpoints, create_mesh, locate_entities_boundary

    if comm.rank == 0:
        points, cells = hexahedra(geometry, n)
    else:
        points, cells = np.empty((0, 3)), np.empty((0, 8), dtype=np.int64)
    lay = layout(geometry)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.hexahedron, 1))
    mesh = create_mesh(comm, cells, points, domain)
    tdim = mesh.topology.dim
    cmap = mesh.topology.index_map(tdim)
    all_cells = np.arange(cmap.size_local + cmap.num_ghosts, dtype=np.int32)
    cell_values = lay.cell_tags(compute_midpoints(mesh, tdim, all_cells))
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = locate_entities_boundary(mesh, tdim - 1, lambda x: np.full(x.shape[1], True))
    facet_values = lay.facet_tags(compute_midpoints(mesh, tdim - 1, facets))
    return MeshData(mesh, _meshtags(mesh, tdim, all_cells, cell_values),
                    _meshtags(mesh, tdim - 1, facets, facet_values), geometry)


def create_hex_mesh(geometry: JointGeometry, comm: MPI.Comm = MPI.COMM_WORLD):
    """The joint half-model as straight-sided hexahedra of ``geometry.divisions`` (>= 1)
    divisions (module docstring), distributed over ``comm`` (collective): a
    fem.mesh.data.MeshData."""
    return _distributed(geometry, geometry.divisions, comm)


def create_hex_finger_mesh(geometry: FingerGeometry, comm: MPI.Comm = MPI.COMM_WORLD):
    """The finger half-model as straight-sided hexahedra, every joint of its own shape and
    of ``geometry.joint.divisions`` (>= 1) divisions (module docstring), distributed over
    ``comm`` (collective): a fem.mesh.data.MeshData tagged by fem.mesh.geometry.finger_tags."""
    return _distributed(geometry, geometry.joint.divisions, comm)
