"""ASE's Langevin thermostat driving each calculator.

With conservative settings (no damping, no friction) the kinetic energy
reaches equipartition: the time-averaged temperature lies within 5 % of the
target.  With damping in the model, the model takes energy out that the
thermostat's noise does not account for (its fluctuation-dissipation balance
knows only its own friction), so the steady state lies below the target and
stays there.  ``temperature_K`` is in kelvin whatever the scene's units:
ASE's thermostat uses ``kT = temperature_K * ase.units.kB`` in the scene's
energy unit (8.617e-5 energy units per kelvin; in reduced units pick
``temperature_K = kT / ase.units.kB``).
"""

import numpy as np
import pytest
from ase import units
from ase.md.langevin import Langevin

from test_properties import scene
from test_stable_timestep import CASES

EQUILIBRATE, AVERAGE, EVERY = 1500, 3000, 5


def thermostat_run(model):
    """Time-averaged temperature over the target, from rest."""
    atoms = CASES[model]() if model in CASES else scene(model, seed=0)
    atoms.set_velocities(np.zeros((len(atoms), 3)))
    estimate = atoms.calc.stable_timestep(atoms)
    dt = 0.2 * estimate
    atoms.calc.set(timestep=dt)  # shear history advances by the thermostat's step
    # a thermal speed of a thousandth of a particle spacing per estimate
    spacing = np.median(np.linalg.norm(np.diff(atoms.positions, axis=0), axis=1))
    kt = float(np.mean(atoms.get_masses())) * (1e-3 * spacing / estimate) ** 2
    target = kt / units.kB
    dyn = Langevin(atoms, dt, temperature_K=target, friction=0.02 / dt, fixcm=False,
                   rng=np.random.default_rng(0))
    dyn.run(EQUILIBRATE)
    samples = []
    for _ in range(AVERAGE // EVERY):
        dyn.run(EVERY)
        samples.append(atoms.get_temperature())
    assert np.isfinite(atoms.get_forces()).all()
    return float(np.mean(samples)) / target


@pytest.mark.parametrize("model", ["spring", "pmb", "lps", "hooke"])
def test_conservative_models_reach_the_target_temperature(model):
    assert thermostat_run(model) == pytest.approx(1.0, abs=0.05)


@pytest.mark.filterwarnings("ignore::ase_bpm.SpinNotIntegratedWarning")  # translation only
@pytest.mark.parametrize("model", ["spring-damped", "hooke-damped"])
def test_damped_models_settle_below_the_target(model):
    ratio = thermostat_run(model)
    assert 0.05 < ratio < 0.95
