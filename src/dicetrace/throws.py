"""Throws as a hand throws them: a full starting state per throw, drawn from a stated distribution.

A die leaves a hand at a random orientation, some height above the table, moving
and spinning.  :class:`HandThrow` is that distribution, with every range stated:

- the orientation uniform over all rotations (Haar measure, scipy's
  ``Rotation.random``), so no face is favoured by how the die is held;
- the height of its centre of mass uniform in ``height_cm``;
- its horizontal velocity of a speed uniform in ``speed_cm_s``, in a direction
  uniform in the plane, and its vertical velocity uniform in ``vz_cm_s``;
- its angular velocity of a size uniform in ``spin_rad_s``, about an axis uniform
  on the sphere; its angular momentum is then L = I·ω with the body's inertia
  tensor in the world frame, R·I_b·Rᵀ (``dicetrace.body``), in the preset's
  sign convention.

No measurement of a hand's throw of a die (release height, speed, spin) could be
found to set these ranges (``dicetrace.materials.LITERATURE``): the default,
:data:`CASUAL`, is a casual throw onto a table chosen before any comparison, and
:data:`THROWS` holds two more, a gentle and a vigorous one, whose spread of results
is the throw model's systematic in any comparison with data.

:meth:`HandThrow.sample` returns the ICs, orientations and heights that
``simulate_batch(ics, orientations=, heights_cm=)`` takes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dicetrace.params import Config, convert_l

__all__ = ["CASUAL", "GENTLE", "HandThrow", "THROWS", "Throws", "VIGOROUS"]


def _range(name: str, r) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in r)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be two numbers (lo, hi), got {r!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"{name} must be two finite numbers lo <= hi, got {r!r}")
    return lo, hi


@dataclass(frozen=True)
class Throws:
    """Starting states of n throws: ``ics`` (n, 6) in the preset's L convention, ``orientations`` (n, 4) unit
    quaternions x, y, z, w (world from body), ``heights_cm`` (n,) start heights of the centre of mass."""

    ics: np.ndarray
    orientations: np.ndarray
    heights_cm: np.ndarray

    def __len__(self) -> int:
        return len(self.ics)


@dataclass(frozen=True)
class HandThrow:
    """A distribution of hand throws (see the module docstring): each range (lo, hi) is sampled uniformly.

    Units: cm, cm/s, rad/s.  ``height_cm`` is the centre of mass's start height; a throw whose die would reach
    below the table is drawn again at the same orientation, higher (its lowest corner just above the table).
    """

    name: str = "casual"
    height_cm: tuple[float, float] = (8.0, 20.0)
    speed_cm_s: tuple[float, float] = (30.0, 120.0)
    vz_cm_s: tuple[float, float] = (-60.0, 20.0)
    spin_rad_s: tuple[float, float] = (5.0, 30.0)

    def __post_init__(self) -> None:
        for field in ("height_cm", "speed_cm_s", "vz_cm_s", "spin_rad_s"):
            object.__setattr__(self, field, _range(field, getattr(self, field)))
        if self.speed_cm_s[0] < 0 or self.spin_rad_s[0] < 0:
            raise ValueError("speed_cm_s and spin_rad_s are sizes: their ranges must be >= 0")

    def sample(self, n: int, config: Config, seed: int) -> Throws:
        """``n`` throws of the die of ``config`` (its body and L convention), reproducibly from ``seed``."""
        from scipy.spatial.transform import Rotation  # scipy: only when throws are drawn

        if int(n) != n or n < 1:
            raise ValueError(f"n must be a whole number >= 1, got {n!r}")
        n = int(n)
        rng = np.random.default_rng(seed)
        rot = Rotation.random(n, random_state=rng)
        R = rot.as_matrix()
        h = rng.uniform(*self.height_cm, n)
        speed = rng.uniform(*self.speed_cm_s, n)
        heading = rng.uniform(0.0, 2.0 * math.pi, n)
        vz = rng.uniform(*self.vz_cm_s, n)
        spin = rng.uniform(*self.spin_rad_s, n)
        axis = rng.normal(size=(n, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        omega = spin[:, None] * axis
        body = config.preset.body
        inertia_world = np.einsum("nij,jk,nlk->nil", R, body.inertia, R)  # R·I_b·Rᵀ
        L = np.einsum("nij,nj->ni", inertia_world, omega)  # physical sign (docs/model.md §4)
        ics = np.c_[speed * np.cos(heading), speed * np.sin(heading), vz, L]
        ics = convert_l(ics, "physical", config.preset.l_convention)
        lowest = np.einsum("kj,nj->nk", body.node_offsets_cm, R[:, 2, :]).min(axis=1)
        h = np.maximum(h, -lowest + 1e-3)  # never below the table
        return Throws(ics=np.ascontiguousarray(ics), orientations=rot.as_quat(canonical=True),
                      heights_cm=np.ascontiguousarray(h))


#: A casual throw onto a table, the default: released 8-20 cm up, 0.3-1.2 m/s across, spinning at 5-30 rad/s.
CASUAL = HandThrow()
#: A gentle one: a low release, slow, little spin.
GENTLE = HandThrow(name="gentle", height_cm=(5.0, 10.0), speed_cm_s=(10.0, 50.0), vz_cm_s=(-20.0, 10.0),
                   spin_rad_s=(2.0, 10.0))
#: A vigorous one: higher, faster, spinning hard.
VIGOROUS = HandThrow(name="vigorous", height_cm=(15.0, 30.0), speed_cm_s=(80.0, 200.0), vz_cm_s=(-100.0, 30.0),
                     spin_rad_s=(20.0, 60.0))
#: The throw models a comparison with data runs, by name: their spread is its throw-model systematic.
THROWS = {t.name: t for t in (CASUAL, GENTLE, VIGOROUS)}
