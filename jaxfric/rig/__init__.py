"""Hydraulic test rig: simulator, measurement pipeline and loaders (docs/algorithms.md §7).

Typical use::

    import jax
    from jaxfric import rig

    r = rig.Rig()                                  # default low-speed press rig (SI units)
    rec = rig.simulate(r, jax.random.key(0))        # 2000 samples at 128 Hz + ground truth
    data = rig.estimate_friction(rec.measurements(), r.cylinder)   # FrictionData, 1600/400 split
    data.train(), data.valid()
    data = rig.synthetic_friction_data(jax.random.key(0))          # the same two steps in one call

Recorded data: [`load_measurements`][jaxfric.rig.load_measurements] (raw x, p1, p2, load) or
[`load_friction_pairs`][jaxfric.rig.load_friction_pairs] (velocity/friction) from CSV files or arrays.
"""

from .data import FrictionData, Measurements
from .friction import friction_force, sliding_levels
from .emps import EMPSRecording, emps_friction_data, idim_ls, load_emps
from .io import IrregularSamplingWarning, load_friction_pairs, load_measurements, resample_uniform
from .params import Controller, Cylinder, Load, Rig, SealFriction, Valve, piston_areas
from .pipeline import butterworth_sos, differentiate, estimate_friction, force_balance, lowpass
from .stats import CoulombLevels, coulomb_levels
from .synthetic import synthetic_friction_data
from .simulator import RigRecord, Sensors, default_velocity_profile, load_force, simulate

__all__ = ["Controller", "EMPSRecording", "CoulombLevels", "Cylinder", "FrictionData",
           "IrregularSamplingWarning", "Load", "Measurements", "Rig", "RigRecord", "SealFriction", "Sensors",
           "Valve", "butterworth_sos", "coulomb_levels", "default_velocity_profile", "differentiate",
           "emps_friction_data", "estimate_friction", "force_balance", "idim_ls", "friction_force",
           "load_force", "load_emps", "load_friction_pairs", "load_measurements", "lowpass", "piston_areas",
           "resample_uniform", "simulate", "sliding_levels", "synthetic_friction_data"]
