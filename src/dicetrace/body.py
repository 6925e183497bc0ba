"""The die's body, written once: its nodes, its faces, its mass, its inertia and where its centre of mass lies.

Bottom layer (numpy only).  Units are the 2019 program's (docs/model.md §2):
centimetres and node masses; the die's mass is 8 (eight corner nodes of
mass 1), whatever its shape.

The box has half-extents (a, b, c) along its body axes x, y, z (the cube:
a = b = c = ``Preset.half_side_cm``).  Node k + 1 (k = 0..7) sits at the
corner ``NODE_SIGNS[k] · (a, b, c)`` of the box; face f (1..6) is the side
of the box that ``FACE_AXES[f - 1]`` names and its four nodes are
``FACE_NODES[f]``; opposite faces add up to 7.  A die is uniform, or carries
a point load: a share ``load_fraction`` of its mass at ``load_cm`` (body
frame, from the box's centre), which moves its centre of mass to
``load_fraction · load_cm`` and changes its inertia (a loaded die).  The node
offsets the kernels move are measured from the centre of mass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Body-frame corner of node k + 1 (row k) in units of the half-extents: node = 1 + 4[x>0] + 2[y>0] + [z>0]
#: (docs/model.md §3): node 1 = (−1, −1, −1), node 8 = (+1, +1, +1).
NODE_SIGNS = np.array(
    [[(-1.0, 1.0)[(k >> 2) & 1], (-1.0, 1.0)[(k >> 1) & 1], (-1.0, 1.0)[k & 1]] for k in range(8)]
)
NODE_SIGNS.setflags(write=False)

#: Face f (1..6) lies on the side ``sign`` of body axis ``axis``: FACE_AXES[f - 1] = (axis, sign).
FACE_AXES = ((0, -1), (1, -1), (2, -1), (2, +1), (1, +1), (0, +1))
#: The nodes (1-based) of each face: those whose corner lies on that side.
FACE_NODES: dict[int, tuple[int, int, int, int]] = {
    f: tuple(k + 1 for k in range(8) if NODE_SIGNS[k, axis] == sign) for f, (axis, sign) in enumerate(FACE_AXES, 1)
}
#: The same, 0-based, one row per face in face order (the recording's plates).
FACE_NODE_ROWS = np.array([[n - 1 for n in FACE_NODES[f]] for f in range(1, 7)])
#: Bitmask of each face's nodes (bit k = node k + 1): the contact sets' encoding.
FACE_NODE_MASK: dict[int, int] = {f: sum(1 << (n - 1) for n in nodes) for f, nodes in FACE_NODES.items()}
#: Outward unit normal of each face in the body frame (face f → row f − 1).
FACE_NORMALS = np.zeros((6, 3))
for _f, (_axis, _sign) in enumerate(FACE_AXES):
    FACE_NORMALS[_f, _axis] = _sign
FACE_NORMALS.setflags(write=False)

#: The die's mass in node masses (eight corner nodes of mass 1).
MASS = 8.0


def rotations(node_offsets) -> np.ndarray:
    """World-from-body rotations (n, 3, 3) of a rigid body read off its node offsets (n, 8, 3), any box and centre
    of mass.

    Column j of R is Σ_k sign_kj · x_k = 8·h_j·(body axis j in the world frame): each axis's signs sum to zero
    over the corners, so the centre of mass's shift drops out.  8·h_j is the column's length at the start (a rigid
    body's offsets keep their lengths): the cube's 8·half exactly when it starts unturned.
    """
    cols = np.einsum("kj,nki->nij", NODE_SIGNS, np.asarray(node_offsets, dtype=np.float64))
    return cols / np.linalg.norm(cols[0], axis=0)


def face_of_top4() -> np.ndarray:
    """The face (1..6) whose four nodes an 8-bit mask names (bit k = node k + 1), 0 where they are no face: what
    the kernels read the outcome from (the four highest nodes)."""
    table = np.zeros(256, dtype=np.int8)
    for f, mask in FACE_NODE_MASK.items():
        table[mask] = f
    return table


@dataclass(frozen=True)
class Body:
    """A box of half-extents ``half_extents_cm`` (cm, along the body axes x, y, z), of mass 8, uniform or with a
    point load: a share ``load_fraction`` (0 ≤ · < 1) of the mass at ``load_cm`` (cm, body frame, from the box's
    centre, inside the box).

    Everything else follows (:attr:`com_cm`, :attr:`node_offsets_cm`, :attr:`inertia`, :attr:`face_heights_cm`,
    :attr:`tip_barriers_cm`).
    """

    half_extents_cm: tuple[float, float, float] = (1.0, 1.0, 1.0)
    load_fraction: float = 0.0
    load_cm: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        h = tuple(float(v) for v in self.half_extents_cm)
        if len(h) != 3 or not all(math.isfinite(v) and v > 0 for v in h):
            raise ValueError(f"half_extents_cm must be three finite numbers > 0, got {self.half_extents_cm!r}")
        object.__setattr__(self, "half_extents_cm", h)
        w = float(self.load_fraction)
        if not (math.isfinite(w) and 0.0 <= w < 1.0):
            raise ValueError(f"load_fraction must be a number in [0, 1), got {self.load_fraction!r}")
        object.__setattr__(self, "load_fraction", w)
        p = tuple(float(v) for v in self.load_cm)
        if len(p) != 3 or not all(math.isfinite(v) for v in p):
            raise ValueError(f"load_cm must be three finite numbers, got {self.load_cm!r}")
        if any(abs(v) > e for v, e in zip(p, h)):
            raise ValueError(f"load_cm {p!r} lies outside the box of half-extents {h!r}")
        object.__setattr__(self, "load_cm", p)

    @classmethod
    def cube(cls, half_side_cm: float = 1.0) -> "Body":
        return cls((half_side_cm, half_side_cm, half_side_cm))

    @property
    def is_cube(self) -> bool:
        """A uniform cube: its centre of mass at the centre, its inertia isotropic (what ``seed`` models)."""
        a, b, c = self.half_extents_cm
        return a == b == c and self.load_fraction == 0.0

    @property
    def com_cm(self) -> np.ndarray:
        """The centre of mass in the body frame, from the box's centre, cm."""
        return self.load_fraction * np.asarray(self.load_cm)

    @property
    def corners_cm(self) -> np.ndarray:
        """The box's corners (8, 3), node k + 1 in row k, from the box's centre, cm."""
        return NODE_SIGNS * np.asarray(self.half_extents_cm)

    @property
    def node_offsets_cm(self) -> np.ndarray:
        """The nodes' offsets (8, 3) from the centre of mass in the body frame, cm: what the kernels move."""
        return self.corners_cm - self.com_cm

    @property
    def inertia(self) -> np.ndarray:
        """The inertia tensor (3, 3) about the centre of mass in the body frame, node-mass·cm².

        The uniform part, mass 8·(1 − w), is a solid box: diag(b² + c², a² + c², a² + b²)·M/3 about its
        centre; the load, mass 8·w at p; both moved to the centre of mass c = w·p by the parallel-axis
        theorem, I_c = I_o − M·(|c|²·E − c cᵀ).  The cube of half side 1: (16/3)·E.
        """
        a, b, c = self.half_extents_cm
        w = self.load_fraction
        box = np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * (MASS * (1.0 - w) / 3.0)
        p = np.asarray(self.load_cm)
        load = MASS * w * (p @ p * np.eye(3) - np.outer(p, p))
        com = self.com_cm
        return box + load - MASS * (com @ com * np.eye(3) - np.outer(com, com))

    def angular_velocity(self, L: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """ω = R·I⁻¹·Rᵀ·L for angular momenta ``L`` (n, 3) and orientations ``rotation`` (n, 3, 3, world from body):
        the kernels' formula, vectorised (the cube's L / I)."""
        L = np.asarray(L, dtype=np.float64)
        if self.is_cube:
            return L / float(self.inertia[0, 0])
        body_l = np.einsum("nji,nj->ni", rotation, L)  # Rᵀ·L
        return np.einsum("nij,nj->ni", rotation, body_l @ np.linalg.inv(self.inertia).T)

    @property
    def reach_cm(self) -> float:
        """The nodes' largest distance from the centre of mass, cm (the cube's √3·half side)."""
        return float(np.linalg.norm(self.node_offsets_cm, axis=1).max())

    @property
    def inv_mass_node(self) -> float:
        """A bound on a node's inverse effective mass, 1/node-mass: 1/M + r²/I_min (r = :attr:`reach_cm`, I_min the
        smallest principal moment), the most a unit impulse at a node can change its velocity (the cube's 11/16)."""
        return 1.0 / MASS + self.reach_cm ** 2 / float(np.linalg.eigvalsh(self.inertia)[0])

    @property
    def face_heights_cm(self) -> np.ndarray:
        """The height of the centre of mass over the ground (6,) when the die rests on face f (row f − 1), cm."""
        h = np.asarray(self.half_extents_cm)
        com = self.com_cm
        return np.array([h[axis] - sign * com[axis] for axis, sign in FACE_AXES])

    @property
    def tip_barriers_cm(self) -> np.ndarray:
        """How far the centre of mass must rise (6,) to tip the die from face f (row f − 1) onto its nearest edge,
        cm: the least, over the face's four edges, of the distance from the centre of mass to the edge minus its
        height over the face."""
        h = np.asarray(self.half_extents_cm)
        com = self.com_cm
        out = np.empty(6)
        for f, (axis, sign) in enumerate(FACE_AXES):
            down = h[axis] - sign * com[axis]  # the centre's height over this face
            best = math.inf
            for other in range(3):
                if other == axis:
                    continue
                for s in (-1.0, 1.0):
                    side = h[other] - s * com[other]  # horizontal distance to the edge on that side
                    best = min(best, math.hypot(down, side) - down)
            out[f] = best
        return out
