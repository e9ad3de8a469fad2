"""Parametric gmsh geometry builders: the two-chamber bellow joint and a slender beam.

Both builders return the *global* ``gmsh.model`` holding one meshed half-model (z >= 0)
with named physical groups, so the same solver code loads either of them. They only
build and mesh; conversion to DOLFINx lives in :mod:`fem.mesh.build`.

Frame and units (docs/physics.md): mm; x along the joint axis from the proximal face
(x = 0) to the distal face (x = L); y in the bending plane, top chamber at +y;
z normal to the bending plane, z = 0 the symmetry plane.

Joint cross-section along x::

    cap | cell | valley | cell | valley | cell | valley | cell | valley | cell | cap
    3mm                                                                    3mm

* outer height 2*H_out (y in [-10, 10]) at the cells and caps, 2*H_valley in a valley,
  so the outer wall is corrugated between cells;
* a solid spine y in [-s/2, s/2] carries the centre line;
* every chamber wall is ``wall`` thick: each chamber is the union of its cell cavities
  and one channel of height H_valley - wall - s/2 that connects them;
* the distal cap (x in [L - cap, L]) is its own volume so the solver can make it rigid.

Physical groups (the names are the contract with :mod:`fem.physics.problem`):

=================  ====  =====================================================
name               dim   what
=================  ====  =====================================================
``solid``          3     the deformable body
``distal_cap``     3     the end block bonded to the rigid connector
``proximal``       2     x = 0, clamped
``distal``         2     x = L
``symmetry``       2     z = 0, u_z = 0
``top_chamber``    2     walls of the +y chamber (pressurised when P > 0)
``bottom_chamber`` 2     walls of the -y chamber (pressurised when P < 0)
``valley_faces``   2     outer faces of the cells across a valley (self-contact)
=================  ====  =====================================================
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from contract.finger import FingerSpec
from contract.joint import GEOMETRY_KEYS, MAX_DIVISIONS, JointSpec, mesh_text
from contract.spec import JOINT_LENGTH, N_ANCHORS

#: Physical-group tags, shared with fem.physics.problem.
TAGS = {
    "solid": 1, "distal_cap": 2,
    "proximal": 11, "distal": 12, "symmetry": 13,
    "top_chamber": 14, "bottom_chamber": 15, "valley_faces": 16,
}
#: JointGeometry's mesh settings: a finger's joints share them (FingerGeometry)
MESH_KEYS = ("mesh_size", "wall_mesh_size", "divisions", "hex_size")
_EPS = 1e-6
_GMSH_READY = False


#: The paper-fidelity tetrahedron size (mm): fem.mesh.discretisation.PAPER's (1.8 mm P2
#: displacement, the discretisation of the committed datasets, surrogate and finger cases)
#: and JointGeometry's tetrahedral size; named here so that code without dolfinx can use it.
PAPER_MESH_SIZE = 1.8


def mesh_record(value) -> dict:
    """A dataclass's fields as a record (dict), without ``divisions`` on a tetrahedral mesh
    (0) and ``hex_size`` when unset (None): the keys records written before the hexahedra
    lack, so that they read as what they are (JointGeometry, fem.mesh.discretisation's
    Discretisation)."""
    out = asdict(value)
    if not value.divisions:
        del out["divisions"]
    if value.hex_size is None:
        del out["hex_size"]
    return out


@dataclass(frozen=True)
class JointGeometry:
    """Dimensions of the bellow joint half-model (mm). Defaults: docs/physics.md.

    The default mesh is the production one (fem.mesh.discretisation.PRODUCTION, "hex2:3"):
    ``divisions`` n >= 1 meshes the joint with swept Q2 hexahedra (fem.mesh.hexahedra: every
    interval between the profile's breakpoints cut into n, so n elements through every
    wall), and ``hex_size`` S (mm, hexahedra only) grades them: an interval of length d is
    cut into n ceil(d / S) elements (None: n), so walls keep n elements through their
    thickness and long spans get elements of at most S / n. ``divisions=0, hex_size=None``
    meshes tetrahedra instead: ``mesh_size`` is their target edge length (default the
    paper-fidelity PAPER_MESH_SIZE) and ``wall_mesh_size`` (default: ``mesh_size``) the one
    on the chamber walls; on hexahedra the two sizes are unused (but recorded by as_dict,
    as every manifest since hexahedra records them).
    """

    length: float = JOINT_LENGTH
    wall: float = 1.2
    height: float = 20.0           # outer, y in [-height/2, height/2]
    width: float = 14.0            # full; the half-model is z in [0, width/2]
    spine: float = 2.4             # y in [-spine/2, spine/2]
    n_cells: int = 5
    cap: float = 3.0
    valley_height: float = 8.8     # outer height in a valley (y in [-4.4, 4.4])
    valley_width: float = 2.5      # outer gap between two neighbouring cells along x
    mesh_size: float = PAPER_MESH_SIZE   # tetrahedra only: 17,359 P2 nodes at 1.8 mm
    wall_mesh_size: float | None = None
    divisions: int = 2                   # production: hex2:3, 42,105 Q2 nodes (make mesh-study)
    hex_size: float | None = 3.0         # mm, hexahedra only

    def __post_init__(self):
        if not (isinstance(self.divisions, int) and 0 <= self.divisions <= MAX_DIVISIONS):
            raise ValueError(f"divisions must be a whole number in [0, {MAX_DIVISIONS}], not {self.divisions!r}")
        if self.hex_size is not None and not (self.divisions and self.hex_size > 0):
            raise ValueError(f"hex_size = {self.hex_size!r}: a positive size (mm), for hexahedra (divisions > 0) only")
        channel = self.valley_height / 2 - self.wall - self.spine / 2
        if channel <= 0:
            raise ValueError("valley_height leaves no channel between the cells")
        if self.cell_width <= 2 * self.wall:
            raise ValueError("cells are too narrow for their walls")

    @property
    def cell_width(self) -> float:
        """Outer length of one bellow cell along x (mm)."""
        inner = self.length - 2 * self.cap
        return (inner - (self.n_cells - 1) * self.valley_width) / self.n_cells

    def cells(self) -> list[tuple[float, float]]:
        """(x_start, x_end) of every cell's outer wall (mm)."""
        x0, w, g = self.cap, self.cell_width, self.valley_width
        return [(x0 + i * (w + g), x0 + i * (w + g) + w) for i in range(self.n_cells)]

    @property
    def mesh(self) -> str:
        """The mesh in words: ``hexN`` (hexahedra of N divisions), or ``H`` / ``H:W`` (mm)."""
        return mesh_text(self.mesh_size, self.wall_mesh_size, self.divisions, self.hex_size)

    def as_dict(self) -> dict:
        """The fields; ``divisions`` only for a hexahedral mesh and ``hex_size`` only when
        set, so records written before them read as what they are (from_record)."""
        return mesh_record(self)

    @classmethod
    def from_record(cls, record: dict) -> JointGeometry:
        """The geometry an as_dict record describes: an absent ``divisions`` is tetrahedra
        (0) and an absent ``hex_size`` ungraded (None), not the production defaults."""
        return cls(**{"divisions": 0, "hex_size": None, **record})


@dataclass(frozen=True)
class BeamGeometry:
    """A slender rectangular cantilever with a rigid end block, for the elastica checks.

    The flexible part is x in [0, length]; the ``distal_cap`` block x in
    [length, length + cap] carries the loads, so the bending length is exactly
    ``length``. Section: y in [-h/2, h/2], half-width z in [0, b/2].
    """

    length: float = 100.0
    thickness: float = 2.0          # h, in the bending plane
    width: float = 2.0              # b, full
    cap: float = 1.0
    mesh_size: float = 1.0

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class FingerGeometry:
    """A whole finger (contract.finger.FingerSpec) as one half-model in its own frame.

    The finger frame is the joint frame of the first joint, extended: x runs along the
    straight rest finger from the base mount (x = 0) to the fingertip (x = finger.length),
    y in the bending plane, z >= 0 the half-model. Joint part k is the bellow joint of its
    own joint description's shape (contract.joint.JointSpec.shape, GEOMETRY_KEYS) meshed
    with the finger's common mesh settings, those of ``joint`` (its mesh size and wall
    refinement, or its hexahedral divisions and hex_size: ``divisions`` > 0 meshes the
    whole finger with fem.mesh.hexahedra), with its proximal face at finger.rest_start(k):
    :meth:`joint_at`. ``joint`` has the first joint's shape (ValueError otherwise, one
    line: a shape given here would be ignored), so in a finger of one joint shape it is
    every joint. Every rigid part is a solid box of its
    cross-section (y in [-height/2, height/2], z in [0, width/2]), bonded to its
    neighbours' end faces (one conforming mesh), meshed at ``rigid_mesh_size`` (mm).
    """

    finger: FingerSpec
    joint: JointGeometry = JointGeometry()
    rigid_mesh_size: float = 6.0
    #: one JointGeometry per joint part, base to tip (derived: joint_at)
    joints: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        first, mesh = shape_of(self.joint), {k: getattr(self.joint, k) for k in MESH_KEYS}
        shapes = [shape_of(self.finger.parts[k].spec.shape) for k in self.finger.joints]
        joints = tuple(self.joint if shape == first else JointGeometry(**shape, **mesh) for shape in shapes)
        if first != shape_of(joints[0]):
            key = next(k for k in GEOMETRY_KEYS if first[k] != getattr(joints[0], k))
            raise ValueError(f"FingerGeometry: joint.{key} = {first[key]!r} is not the finger's first joint's "
                             f"({getattr(joints[0], key)!r}): every joint takes its own description's shape, "
                             f"joint gives the mesh settings on the first joint's shape")
        object.__setattr__(self, "joints", joints)

    def joint_at(self, k: int) -> JointGeometry:
        """The geometry of joint part k (a part index, finger.joints): its own shape, the
        finger's mesh settings."""
        return self.joints[self.finger.joints.index(k)]

    @property
    def same_shape(self) -> bool:
        """Whether every joint has the first joint's shape (one shape meshed for all)."""
        return all(shape_of(j) == shape_of(self.joint) for j in self.joints)

    @property
    def mesh_size(self) -> float:
        return self.joint.mesh_size

    @property
    def divisions(self) -> int:
        """The joints' hexahedral divisions (fem.mesh.hexahedra meshes the whole finger); 0:
        gmsh tetrahedra."""
        return self.joint.divisions

    @property
    def mesh(self) -> str:
        """The joints' mesh in words (JointGeometry.mesh): ``hexN``, or ``H`` / ``H:W`` (mm)."""
        return self.joint.mesh

    def as_dict(self) -> dict:
        """``finger``, ``joint`` (the first joint's shape and the mesh settings:
        JointGeometry.as_dict) and ``rigid_mesh_size``; and, only when the joints differ in
        shape, ``joints``: every joint's shape (GEOMETRY_KEYS, mm), base to tip, so a
        finger of one joint shape records what it always did."""
        out = {"finger": self.finger.summary(), "joint": self.joint.as_dict(),
               "rigid_mesh_size": self.rigid_mesh_size}
        if not self.same_shape:
            out["joints"] = [shape_of(j) for j in self.joints]
        return out


def shape_of(joint) -> dict:
    """{GEOMETRY_KEYS: value} of a JointGeometry or a contract.joint.BellowShape (mm)."""
    return {k: getattr(joint, k) for k in GEOMETRY_KEYS}


def finger_tags(finger: FingerSpec) -> dict[str, int]:
    """Physical-group tags of a finger model (the contract with fem.solvers.finger).

    Shared names keep TAGS' values (``proximal``, ``symmetry``, ``valley_faces``); per
    part k: ``part{k}`` (a joint's deformable body, or a rigid part), ``cap{k}`` (a joint's
    distal cap), ``top{k}`` and ``bottom{k}`` (a joint's chamber walls)."""
    tags = {name: TAGS[name] for name in ("proximal", "symmetry", "valley_faces")}
    for k, part in enumerate(finger.parts):
        tags[f"part{k}"] = 100 + k
        if part.kind == "joint":
            tags.update({f"cap{k}": 200 + k, f"top{k}": 300 + k, f"bottom{k}": 400 + k})
    return tags


def _init_gmsh(name: str):
    import gmsh

    global _GMSH_READY
    if not _GMSH_READY:   # gmsh 4.8 has no isInitialized()
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 1)
        _GMSH_READY = True
    gmsh.clear()
    gmsh.model.add(name)
    return gmsh


def _surfaces_in_box(gmsh, xmin, ymin, zmin, xmax, ymax, zmax) -> list[int]:
    ents = gmsh.model.getEntitiesInBoundingBox(
        xmin - _EPS, ymin - _EPS, zmin - _EPS, xmax + _EPS, ymax + _EPS, zmax + _EPS, 2)
    return [tag for _, tag in ents]


def _check_groups(groups: dict[str, tuple[int, list[int]]]) -> None:
    for name, (_, tags) in groups.items():
        if not tags:
            raise RuntimeError(f"geometry: physical group '{name}' is empty")


def _add_groups(gmsh, groups: dict[str, tuple[int, list[int]]]) -> None:
    _check_groups(groups)
    for name, (dim, tags) in groups.items():
        gmsh.model.addPhysicalGroup(dim, sorted(set(tags)), TAGS[name])
        gmsh.model.setPhysicalName(dim, TAGS[name], name)


def build_joint(geo: JointGeometry = JointGeometry()):
    """Build and mesh the joint half-model; return the global ``gmsh.model``.

    Only the quarter y >= 0 is meshed; its mesh is then mirrored to y < 0 node by node
    (:func:`_mirror_mesh_y`), so the discrete problem has the exact y-mirror symmetry of
    docs/physics.md and the solver reproduces it to solver tolerance, not mesh error.
    Call on rank 0 only, then convert with :func:`fem.mesh.build.create_mesh`.
    """
    gmsh = _init_gmsh("bellow_joint")
    occ = gmsh.model.occ
    L, H, Z = geo.length, geo.height / 2, geo.width / 2
    solid = _joint_quarter(occ, geo)
    # Split off the distal cap as its own volume; the cutter is exactly the (solid) cap
    # block, so the fragments are the cap and the rest, sharing a conforming interface.
    cutter = occ.addBox(L - geo.cap, 0, 0, geo.cap, H, Z)
    occ.fragment(solid, [(3, cutter)])
    occ.synchronize()
    vols = [tag for _, tag in gmsh.model.getEntities(3)]
    keep_cap = [v for v in vols if gmsh.model.getBoundingBox(3, v)[0] > L - geo.cap - _EPS]
    keep_body = [v for v in vols if v not in keep_cap]

    sym = _surfaces_in_box(gmsh, -1, -1, 0, L + 1, H + 1, 0)
    top, valley = _joint_faces(gmsh, geo, 0.0, sym)
    groups = {
        "solid": (3, keep_body), "distal_cap": (3, keep_cap),
        "proximal": (2, _surfaces_in_box(gmsh, 0, 0, 0, 0, H, Z)),
        "distal": (2, _surfaces_in_box(gmsh, L, 0, 0, L, H, Z)),
        "symmetry": (2, sym), "top_chamber": (2, top), "valley_faces": (2, valley),
    }
    _check_groups(groups)   # the groups are added to the mirrored model
    _mesh(gmsh, geo.mesh_size, geo.wall_mesh_size, top, geo.wall)
    _mirror_mesh_y(gmsh, groups, {"top_chamber": "bottom_chamber"})
    return gmsh.model


def _joint_quarter(occ, geo: JointGeometry, x0: float = 0.0) -> list[tuple[int, int]]:
    """The joint's solid quarter (y >= 0, z >= 0), proximal face at x = x0: OCC dim-tags."""
    L, t, s = geo.length, geo.wall, geo.spine
    H, Hv, Z = geo.height / 2, geo.valley_height / 2, geo.width / 2
    cells = [(x0 + a, x0 + b) for a, b in geo.cells()]

    # Outer body (y >= 0): a core bar of valley height, plus caps and cells at full height.
    parts = [occ.addBox(x0, 0, 0, L, Hv, Z),
             occ.addBox(x0, 0, 0, geo.cap, H, Z),
             occ.addBox(x0 + L - geo.cap, 0, 0, geo.cap, H, Z)]
    parts += [occ.addBox(a, 0, 0, b - a, H, Z) for a, b in cells]
    body, _ = occ.fuse([(3, parts[0])], [(3, p) for p in parts[1:]])

    # Top chamber cavity: one channel joining the cell pockets.
    x_in0, x_in1 = x0 + geo.cap, x0 + L - geo.cap
    pieces = [occ.addBox(x_in0, s / 2, 0, x_in1 - x_in0, Hv - t - s / 2, Z - t)]
    for i, (c0, c1) in enumerate(cells):
        a = c0 if i == 0 else c0 + t
        b = c1 if i == len(cells) - 1 else c1 - t
        pieces.append(occ.addBox(a, s / 2, 0, b - a, H - t - s / 2, Z - t))
    cavity, _ = occ.fuse([(3, pieces[0])], [(3, p) for p in pieces[1:]])
    solid, _ = occ.cut(body, cavity)
    return solid


def _joint_faces(gmsh, geo: JointGeometry, x0: float, sym: list[int]) -> tuple[list[int], list[int]]:
    """(top-chamber wall surfaces, valley faces) of the joint at x0, after synchronize.

    The two faces across each valley are meshed translation-periodically: every node has
    an exact partner, which fem.physics.contact's node-to-node pairs need."""
    L, t, s = geo.length, geo.wall, geo.spine
    H, Hv, Z = geo.height / 2, geo.valley_height / 2, geo.width / 2
    cells = [(x0 + a, x0 + b) for a, b in geo.cells()]
    box = _surfaces_in_box(gmsh, x0 + geo.cap, s / 2, 0, x0 + L - geo.cap, H - t, Z - t)
    top = [f for f in box if f not in sym]
    valley = []
    for (_, x1), (x2, _) in zip(cells[:-1], cells[1:]):
        left = _surfaces_in_box(gmsh, x1, Hv, 0, x1, H, Z)
        right = _surfaces_in_box(gmsh, x2, Hv, 0, x2, H, Z)
        shift = [1, 0, 0, x2 - x1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
        gmsh.model.mesh.setPeriodic(2, right, left, shift)
        valley += left + right
    return top, valley


def _mirror_mesh_y(gmsh, groups: dict[str, tuple[int, list[int]]], swap: dict[str, str],
                   group_tags: dict[str, int] = TAGS) -> None:
    """Replace the meshed quarter (y >= 0) by a discrete model of it plus its y-mirror.

    Nodes on y = 0 are shared; mirrored tetrahedra get two nodes swapped to keep a
    positive orientation. A group named in ``swap`` sends its mirror image to the other
    name (top chamber -> bottom chamber); every other group keeps both halves.
    """
    tags, xyz, _ = gmsh.model.mesh.getNodes()
    tags = tags.astype(np.int64)
    xyz = xyz.reshape(-1, 3)
    n = len(tags)
    on_plane = np.abs(xyz[:, 1]) < 1e-9
    # dolfinx wants node tags 1..N: originals keep their rank, mirrors follow.
    index = np.zeros(tags.max() + 1, dtype=np.int64)
    index[tags] = np.arange(1, n + 1)
    mirror_of = np.arange(1, n + 1)
    mirror_of[~on_plane] = n + 1 + np.arange((~on_plane).sum())
    renumber = lambda c: index[c]
    lookup = lambda c: mirror_of[index[c] - 1]
    conn = {}
    for name, (dim, ents) in groups.items():
        etype = 4 if dim == 3 else 2          # linear tetrahedra / triangles
        nper = 4 if dim == 3 else 3
        blocks = []
        for e in ents:
            types, _, nodes = gmsh.model.mesh.getElements(dim, e)
            blocks += [n.reshape(-1, nper) for t, n in zip(types, nodes) if t == etype]
        c = np.vstack(blocks).astype(np.int64)
        m = lookup(c)
        m[:, [0, 1]] = m[:, [1, 0]]
        c = renumber(c)
        conn.setdefault(name, (dim, []))[1].append(c)
        conn.setdefault(swap.get(name, name), (dim, []))[1].append(m)

    new_xyz = np.vstack([xyz, xyz[~on_plane] * [1.0, -1.0, 1.0]])
    new_tags = np.arange(1, len(new_xyz) + 1)
    gmsh.model.add("bellow_joint_mirrored")
    next_elem = 1
    for i, (name, (dim, blocks)) in enumerate(conn.items(), start=1):
        c = np.vstack(blocks)
        gmsh.model.addDiscreteEntity(dim, i)
        if i == 1:
            gmsh.model.mesh.addNodes(dim, i, new_tags, new_xyz.ravel())
        etags = np.arange(next_elem, next_elem + len(c))
        next_elem += len(c)
        gmsh.model.mesh.addElementsByType(i, 4 if dim == 3 else 2, etags, c.ravel())
        gmsh.model.addPhysicalGroup(dim, [i], group_tags[name])
        gmsh.model.setPhysicalName(dim, group_tags[name], name)


def build_beam(geo: BeamGeometry = BeamGeometry()):
    """Build and mesh the slender cantilever half-model; return the global ``gmsh.model``."""
    gmsh = _init_gmsh("beam")
    occ = gmsh.model.occ
    L, h, Z = geo.length, geo.thickness, geo.width / 2
    beam = occ.addBox(0, -h / 2, 0, L, h, Z)
    cap = occ.addBox(L, -h / 2, 0, geo.cap, h, Z)
    occ.fragment([(3, beam)], [(3, cap)])
    occ.synchronize()
    vols = [tag for _, tag in gmsh.model.getEntities(3)]
    body = [v for v in vols if gmsh.model.getBoundingBox(3, v)[3] < L + _EPS]
    capv = [v for v in vols if v not in body]
    Lt = L + geo.cap
    _add_groups(gmsh, {
        "solid": (3, body), "distal_cap": (3, capv),
        "proximal": (2, _surfaces_in_box(gmsh, 0, -h, 0, 0, h, Z)),
        "distal": (2, _surfaces_in_box(gmsh, Lt, -h, 0, Lt, h, Z)),
        "symmetry": (2, _surfaces_in_box(gmsh, 0, -h, 0, Lt, h, 0)),
    })
    _mesh(gmsh, geo.mesh_size)
    return gmsh.model


def build_finger(geo: FingerGeometry):
    """Build and mesh the finger half-model (FingerGeometry); return the global ``gmsh.model``.

    Every joint part is its own shape (FingerGeometry.joint_at) at its rest start, with its
    distal cap split off as in :func:`build_joint`; one OCC fragment of every part and cap
    cutter bonds neighbouring parts through shared, conforming faces whatever their
    cross-sections. As in :func:`build_joint`, only y >= 0 is meshed and then mirrored
    node by node, so the finger keeps the exact y-mirror symmetry. Call on rank 0 only.
    """
    gmsh = _init_gmsh("finger")
    occ = gmsh.model.occ
    finger = geo.finger
    spans = [(finger.rest_start(k), finger.rest_start(k) + p.length) for k, p in enumerate(finger.parts)]
    solids, cutters = [], []
    for k, (part, (x0, x1)) in enumerate(zip(finger.parts, spans)):
        if part.kind == "joint":
            jg = geo.joint_at(k)
            solids += _joint_quarter(occ, jg, x0)
            cutters.append((3, occ.addBox(x1 - jg.cap, 0, 0, jg.cap, jg.height / 2, jg.width / 2)))
        else:
            solids.append((3, occ.addBox(x0, 0, 0, part.length, part.height / 2, part.width / 2)))
    # One fragment of every part and cap cutter: bonded parts share conforming faces.
    occ.fragment(solids, cutters)
    occ.synchronize()

    tags = finger_tags(finger)
    vols = {v: gmsh.model.getBoundingBox(3, v) for _, v in gmsh.model.getEntities(3)}
    ymax = max(b[4] for b in vols.values())
    sym = _surfaces_in_box(gmsh, -1, -1, 0, finger.length + 1, ymax + 1, 0)
    groups = {"proximal": (2, _surfaces_in_box(gmsh, 0, 0, 0, 0, ymax, ymax)),
              "symmetry": (2, sym), "valley_faces": (2, [])}
    swap, walls, regions = {}, {}, []
    for k, (part, (x0, x1)) in enumerate(zip(finger.parts, spans)):
        inside = [v for v, b in vols.items() if b[0] > x0 - _EPS and b[3] < x1 + _EPS]
        if part.kind == "joint":
            jg = geo.joint_at(k)
            cap = [v for v in inside if vols[v][0] > x1 - jg.cap - _EPS]
            groups[f"part{k}"] = (3, [v for v in inside if v not in cap])
            groups[f"cap{k}"] = (3, cap)
            top, valley = _joint_faces(gmsh, jg, x0, sym)
            groups[f"top{k}"] = (2, top)
            groups["valley_faces"][1].extend(valley)
            swap[f"top{k}"] = f"bottom{k}"
            walls.setdefault(jg.wall, []).extend(top)
            regions.append((x0, x1))
        else:
            groups[f"part{k}"] = (3, inside)
    _check_groups(groups)
    _mesh_regions(gmsh, geo.joint.mesh_size, geo.joint.wall_mesh_size, walls, regions, geo.rigid_mesh_size)
    _mirror_mesh_y(gmsh, groups, swap, tags)
    return gmsh.model


def _mesh(gmsh, size: float, wall_size: float | None = None, wall_surfaces: list[int] = (),
          wall_thickness: float = 0.0) -> None:
    """Mesh the model at edge length ``size`` (mm); ``wall_size`` within one wall
    thickness of ``wall_surfaces``."""
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.25 * size)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)   # Delaunay: robust on thin walls
    if wall_size is not None and wall_surfaces:
        gmsh.model.mesh.field.setAsBackgroundMesh(
            _wall_field(gmsh, wall_surfaces, wall_size, wall_thickness, size, size))
        gmsh.option.setNumber("Mesh.MeshSizeMin", min(0.25 * size, 0.5 * wall_size))
    gmsh.model.mesh.generate(3)
    gmsh.model.mesh.optimize("")  # default tetrahedral optimiser (no Netgen in Debian gmsh)


def _wall_field(gmsh, surfaces: list[int], wall_size: float, wall_thickness: float, size: float,
                far_size: float) -> int:
    """A size field: wall_size within one wall thickness of ``surfaces`` (so through the
    whole wall), growing to far_size over the next ``size`` mm. (gmsh 4.8 has no
    "Constant" field.) Returns its tag."""
    f = gmsh.model.mesh.field
    dist = f.add("Distance")
    f.setNumbers(dist, "SurfacesList", surfaces)
    ramp = f.add("Threshold")
    f.setNumber(ramp, "InField", dist)
    f.setNumber(ramp, "SizeMin", wall_size)
    f.setNumber(ramp, "SizeMax", far_size)
    f.setNumber(ramp, "DistMin", wall_thickness)
    f.setNumber(ramp, "DistMax", wall_thickness + size)
    return ramp


def _mesh_regions(gmsh, size: float, wall_size: float | None, walls: dict[float, list[int]],
                  regions: list[tuple[float, float]], outside_size: float) -> None:
    """Mesh the finger: background size field the Min over a Box per region ((x0, x1)
    slabs, the joints: ``size`` inside, ``outside_size`` (mm) beyond, the rigid parts)
    and, with wall_size, one wall Threshold of :func:`_mesh` per wall thickness (``walls``:
    {thickness mm: its chamber-wall surfaces}; joints of one wall share it), growing to
    outside_size."""
    f = gmsh.model.mesh.field
    fields = []
    for x0, x1 in regions:
        box = f.add("Box")
        # a little beyond the region's end faces: the bonded faces are meshed at ``size``
        for key, value in (("VIn", size), ("VOut", outside_size), ("XMin", x0 - 0.5 * size),
                           ("XMax", x1 + 0.5 * size), ("YMin", -1e3), ("YMax", 1e3),
                           ("ZMin", -1e3), ("ZMax", 1e3)):
            f.setNumber(box, key, value)
        fields.append(box)
    smallest = size
    if wall_size is not None and walls:
        fields += [_wall_field(gmsh, surfaces, wall_size, thickness, size, outside_size)
                   for thickness, surfaces in walls.items()]
        smallest = min(size, wall_size)
    both = f.add("Min")
    f.setNumbers(both, "FieldsList", fields)
    f.setAsBackgroundMesh(both)
    gmsh.option.setNumber("Mesh.MeshSizeMax", outside_size)
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.25 * smallest)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)
    gmsh.model.mesh.generate(3)
    gmsh.model.mesh.optimize("")


def anchor_points(length: float, n: int = N_ANCHORS) -> np.ndarray:
    """Material anchor points X_i = (i·L/n, 0, 0), i = 1..n (docs/physics.md). Shape (n, 3), mm."""
    x = np.arange(1, n + 1) * length / n
    return np.column_stack([x, np.zeros(n), np.zeros(n)])


def finger_joints(finger: FingerSpec) -> list[JointSpec]:
    """The joint description of every joint part, base to tip (contract.finger: a part's
    own joint file, or the paper's joint)."""
    return [finger.parts[k].spec for k in finger.joints]


def pressure_limits(finger: FingerSpec) -> np.ndarray:
    """|P_j| bound (MPa) of every joint, base to tip: its input box's pressure_mpa."""
    return np.array([spec.pressure_mpa for spec in finger_joints(finger)])
