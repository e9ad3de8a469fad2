"""A swept hexahedral mesh of the bellow joint half-model (z >= 0), for Q2 elements.

The joint of :func:`fem.geometry.build_joint` is a union of axis-aligned boxes: in the x-y
profile every feature (caps, cells, valleys, pockets, channel, spine, walls) starts and
ends at one of a few coordinates, and along z the chambers run from the symmetry plane
z = 0 to the side wall z in [Z - t, Z]. With the breakpoints (mm; L length, t wall,
s spine, H = height/2, Hv = valley_height/2, Z = width/2, cells [c0_i, c1_i], pockets
[a_i, b_i] with a_0 = c0_0, b_last = c1_last and otherwise a_i = c0_i + t, b_i = c1_i - t)::

    x: 0, cap, a_i, b_i, c0_i, c1_i, L - cap, L
    y: -H, -(H - t), -Hv, -(Hv - t), -s/2, s/2, Hv - t, Hv, H - t, H
    z: 0, Z - t, Z

every box between neighbouring breakpoints is wholly solid, wholly chamber or wholly
outside (a valley gap y > Hv between two cells). The mesh of ``divisions`` n splits every
interval between neighbouring breakpoints into n equal elements: a tensor grid whose
profile layer is a structured quad mesh swept along z; the hexahedra of the chambers
(z < Z - t) and of the valley gaps are left out. So every wall is n elements thick, and
the meshes of n = 1, 2, 3, ... are nested refinements of one another with element size
exactly proportional to 1/n (the Richardson family of fem.mesh_study). The profile is
polygonal, so straight-sided hexahedra represent it exactly.

The y breakpoints of y < 0 are the negatives of those of y >= 0, and the grid is
symmetrised, so the node set is exactly its own y-mirror, node by node, as the
tetrahedral mesh is.

Tags (fem.geometry.TAGS) follow from the exact geometry: cells by their midpoint's x
(``distal_cap`` beyond L - cap, else ``solid``); boundary facets by their midpoint:
``proximal`` x = 0, ``distal`` x = L, ``symmetry`` z = 0, ``top_chamber`` /
``bottom_chamber`` the walls of the closed chamber region at y > 0 / y < 0 (z > 0),
``valley_faces`` the outer cell faces x = c1_i, c0_{i+1} with |y| > Hv. The two faces of
a valley share their (y, z) grid, so every node has the exact partner that
fem.contact's node-to-node pairs need.

Q2 on hexahedra needs quadrature degree 4 (3 x 3 x 3 Gauss points): degree 2 or 3 gives
2 x 2 x 2, which under-integrates the Q2 stiffness (hourglass modes); QUADRATURE is that
degree, and fem.discretisation uses it for every hexahedral discretisation.

Data flow: JointGeometry(divisions=n) -> fem.mesh.create_mesh -> create_hex_mesh ->
fem.mesh.MeshData -> fem.problem / fem.solver, exactly as the gmsh tetrahedra.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fem.geometry import TAGS, JointGeometry

#: quadrature degree of Q2 hexahedra: 3 x 3 x 3 Gauss points (module docstring)
QUADRATURE = 4
_TOL = 1e-6     # mm: coordinates closer than this are one breakpoint


# ---------------------------------------------------------------------- the grid
def pockets(geo: JointGeometry) -> list[tuple[float, float]]:
    """(a, b): x range (mm) of every cell's cavity, as fem.geometry's quarter cuts it."""
    cells, t = geo.cells(), geo.wall
    return [(c0 if i == 0 else c0 + t, c1 if i == len(cells) - 1 else c1 - t)
            for i, (c0, c1) in enumerate(cells)]


def breakpoints(geo: JointGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, z) breakpoints of the joint's boxes (mm), sorted (module docstring; the
    spine is one interval, so y = 0 is no breakpoint)."""
    L, t, s = geo.length, geo.wall, geo.spine
    H, Hv, Z = geo.height / 2, geo.valley_height / 2, geo.width / 2
    x = [0.0, geo.cap, L - geo.cap, L] + [c for cell in geo.cells() for c in cell]
    x += [c for pocket in pockets(geo) for c in pocket]
    y = [v for h in (s / 2, Hv - t, Hv, H - t, H) for v in (h, -h)]
    return _unique(x), _unique(y), _unique([0.0, Z - t, Z])


def _unique(values) -> np.ndarray:
    v = np.sort(np.asarray(values, dtype=float))
    return v[np.concatenate([[True], np.diff(v) > _TOL])]


def subdivide(breaks: np.ndarray, n: int) -> np.ndarray:
    """Node coordinates (mm) of a 1D grid: every interval of ``breaks`` cut into n equal
    elements; the breakpoints themselves are kept exactly."""
    inner = breaks[:-1, None] + np.diff(breaks)[:, None] * np.arange(n)[None, :] / n
    return np.append(inner.ravel(), breaks[-1])


def grid(geo: JointGeometry, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node coordinates (mm) along x, y and z of the tensor grid of ``n`` divisions; y is
    symmetrised, y_i = (y_i - y_{m-1-i}) / 2, so that y_{m-1-i} = -y_i exactly."""
    bx, by, bz = breakpoints(geo)
    gy = subdivide(by, n)
    return subdivide(bx, n), (gy - gy[::-1]) / 2, subdivide(bz, n)


# ---------------------------------------------------------------------- the regions
def in_chamber(geo: JointGeometry, x, y, z, closed: bool = False) -> np.ndarray:
    """Points (mm; arrays) inside a chamber (either sign of y); with ``closed``, on its
    boundary too (up to 1e-6 mm)."""
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
    """Points (mm) in the open gap of a valley, between two cells above |y| = Hv."""
    cells = geo.cells()
    gap = np.zeros(np.shape(x), dtype=bool)
    for (_, x1), (x2, _) in zip(cells[:-1], cells[1:]):
        gap |= (x > x1 + _TOL) & (x < x2 - _TOL)
    return gap & (np.abs(y) > geo.valley_height / 2 + _TOL)


def hexahedra(geo: JointGeometry, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(points (p, 3) mm, cells (m, 8)) of the solid hexahedra of ``n`` divisions, vertices
    in DOLFINx order ((0,0,0), (1,0,0), (0,1,0), (1,1,0), then z = 1); unused grid nodes
    dropped."""
    gx, gy, gz = grid(geo, n)
    nx, ny = len(gx), len(gy)
    mid = [(g[:-1] + g[1:]) / 2 for g in (gx, gy, gz)]
    cx, cy, cz = np.meshgrid(*mid, indexing="ij")
    solid = ~(in_chamber(geo, cx, cy, cz) | in_valley_gap(geo, cx, cy))
    i, j, k = (a.ravel() for a in np.nonzero(solid))

    def node(di, dj, dk):
        return (i + di) + nx * ((j + dj) + ny * (k + dk))

    cells = np.column_stack([node(di, dj, dk) for dk in (0, 1) for dj in (0, 1) for di in (0, 1)])
    used, cells = np.unique(cells, return_inverse=True)
    X, Y, Z = np.meshgrid(gx, gy, gz, indexing="ij")
    xyz = np.column_stack([a.ravel(order="F") for a in (X, Y, Z)])
    return xyz[used], cells.reshape(-1, 8).astype(np.int64)


# ---------------------------------------------------------------------- tags
def facet_markers(geo: JointGeometry, m: np.ndarray) -> np.ndarray:
    """Tag (fem.geometry.TAGS, 0: none) of boundary facets by their midpoints m (k, 3) mm."""
    x, y, z = m.T
    tag = np.zeros(len(m), dtype=np.int32)
    chamber = in_chamber(geo, x, y, z, closed=True) & (z > _TOL)
    tag[chamber & (y > 0)] = TAGS["top_chamber"]
    tag[chamber & (y < 0)] = TAGS["bottom_chamber"]
    cells = geo.cells()
    for (_, x1), (x2, _) in zip(cells[:-1], cells[1:]):
        face = (np.abs(x - x1) < _TOL) | (np.abs(x - x2) < _TOL)
        tag[face & (np.abs(y) > geo.valley_height / 2 + _TOL)] = TAGS["valley_faces"]
    tag[np.abs(z) < _TOL] = TAGS["symmetry"]
    tag[np.abs(x) < _TOL] = TAGS["proximal"]
    tag[np.abs(x - geo.length) < _TOL] = TAGS["distal"]
    return tag


def _meshtags(mesh, dim: int, entities: np.ndarray, values: np.ndarray):
    from dolfinx.mesh import meshtags

    keep = values > 0
    order = np.argsort(entities[keep])
    return meshtags(mesh, dim, entities[keep][order].astype(np.int32), values[keep][order])


def create_hex_mesh(geometry: JointGeometry, comm: MPI.Comm = MPI.COMM_WORLD):
    """The joint half-model as straight-sided hexahedra of ``geometry.divisions`` (>= 1)
    divisions (module docstring), distributed over ``comm`` (collective; rank 0 builds the
    cells): a fem.mesh.MeshData."""
    import ufl
    from dolfinx.mesh import compute_midpoints, create_mesh, locate_entities_boundary

    from fem.mesh import MeshData

    if comm.rank == 0:
        points, cells = hexahedra(geometry, geometry.divisions)
    else:
        points, cells = np.empty((0, 3)), np.empty((0, 8), dtype=np.int64)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.hexahedron, 1))
    mesh = create_mesh(comm, cells, points, domain)
    tdim = mesh.topology.dim
    cmap = mesh.topology.index_map(tdim)
    all_cells = np.arange(cmap.size_local + cmap.num_ghosts, dtype=np.int32)
    cap = compute_midpoints(mesh, tdim, all_cells)[:, 0] > geometry.length - geometry.cap
    cell_values = np.where(cap, TAGS["distal_cap"], TAGS["solid"]).astype(np.int32)
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = locate_entities_boundary(mesh, tdim - 1, lambda x: np.full(x.shape[1], True))
    facet_values = facet_markers(geometry, compute_midpoints(mesh, tdim - 1, facets))
    return MeshData(mesh, _meshtags(mesh, tdim, all_cells, cell_values),
                    _meshtags(mesh, tdim - 1, facets, facet_values), geometry)
