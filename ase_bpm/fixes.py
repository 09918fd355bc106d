"""External force pieces that compose with any ase_bpm calculator.

LAMMPS equivalents: ``fix indent`` (and, for granular scenes, ``fix gravity``
and ``fix wall/gran``).  Pass them to a calculator, ``BPMPeri(...,
fixes=[indenter])``; the calculator evaluates them with the same configuration
and step as its own forces, so they work with any ASE integrator, restart and
cache like the rest.  A piece that moves with time gets ``time = step *
timestep``, the calculator's ``timestep`` parameter (LAMMPS' ``step*dt``).

A piece provides ``forces(atoms, time) -> (f_nc, energy)`` and ``todict()``.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms


class SphericalIndenter:
    """A rigid sphere pushing particles out: LAMMPS ``fix indent K sphere``.

    A particle at distance ``r < R`` from the centre feels ``K (R - r)^2``
    outwards (energy ``K (R - r)^3 / 3``).  The centre moves with constant
    ``velocity``: ``centre(t) = centre + velocity * t``, as the LAMMPS example
    ``variable y equal "v_y0 + step*dt*v_vy"``.

    Parameters: ``k`` (force/distance^2), ``radius`` (distance), ``centre``
    (distance, at time 0), ``velocity`` (distance/time).
    """

    needs_time = True

    def __init__(self, k: float, radius: float, centre, velocity=(0.0, 0.0, 0.0)):
        if not k > 0:
            raise ValueError(f"indenter stiffness k must be positive, got {k!r}")
        if not radius > 0:
            raise ValueError(f"indenter radius must be positive, got {radius!r}")
        self.k, self.radius = float(k), float(radius)
        self.centre = np.asarray(centre, dtype=float).reshape(3)
        self.velocity = np.asarray(velocity, dtype=float).reshape(3)
        if not (np.isfinite(self.centre).all() and np.isfinite(self.velocity).all()):
            raise ValueError("indenter centre and velocity must be finite")

    def centre_at(self, time: float) -> np.ndarray:
        return self.centre + self.velocity * time

    def forces(self, atoms: Atoms, time: float):
        d_nc = atoms.positions - self.centre_at(time)
        r_n = np.sqrt(np.einsum("nc,nc->n", d_nc, d_nc))
        inside = r_n < self.radius
        f_nc = np.zeros_like(d_nc)
        if not inside.any():
            return f_nc, 0.0
        depth = self.radius - r_n[inside]
        rinv = np.divide(1.0, r_n[inside], out=np.zeros_like(depth), where=r_n[inside] > 0)
        f_nc[inside] = d_nc[inside] * (self.k * depth * depth * rinv)[:, None]
        return f_nc, float(np.sum(self.k * depth ** 3 / 3.0))

    def todict(self) -> dict:
        return {"type": "SphericalIndenter", "k": self.k, "radius": self.radius,
                "centre": self.centre.tolist(), "velocity": self.velocity.tolist()}

    def __repr__(self) -> str:
        return (f"SphericalIndenter(k={self.k!r}, radius={self.radius!r}, "
                f"centre={self.centre.tolist()!r}, velocity={self.velocity.tolist()!r})")
