"""Export of a fit (jaxfric.export): the NumPy step and the generated C header reproduce
Fit.predict on a recording; the C one is compiled with the system C compiler."""

import shutil
import subprocess

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric import Fit, models
from jaxfric.models import Scaler


def _velocity(n=1500, dt=1e-3):
    t = np.arange(n) * dt
    v = 0.02 * np.sin(2 * np.pi * 1.7 * t) + 0.006 * np.sin(2 * np.pi * 7.3 * t + 0.4)
    v[300:340] = 0.0  # a standstill: v = 0 exactly
    return v


def _fit(model, theta, v):
    scalers = (Scaler.fit(v), Scaler(lo=np.float64(-35.0), hi=np.float64(42.0))) \
        if model.needs_scaling else (None, None)
    return Fit(model=model, theta=np.asarray(theta, np.float64), velocity_scaler=scalers[0],
               friction_scaler=scalers[1], dt=1e-3, n_train=v.size, n_samples=v.size, metrics={})


def _cases():
    rng = np.random.default_rng(1)
    out = []
    for m in (models.Elman(neurons=6, context_weight_bound=1.0, output_bias=True),
              models.ElmanFull(neurons=4)):
        lo, hi = m.bounds()
        out.append((m, 0.5 * rng.uniform(lo, hi)))
    lugre = models.LuGre()
    out.append((lugre, lugre.from_physical(sigma0=1e6, sigma1=300.0, sigma2=500.0, Fc=20.0, Fs=30.0, vs=5e-3)))
    dahl = models.Dahl(viscous=True)
    out.append((dahl, dahl.from_physical(sigma0=2e5, Fc=15.0, sigma2=100.0)))
    c = models.Coulomb()
    out.append((c, c.from_physical(Fc=20.0, sigma2=200.0)))
    s = models.Stribeck(fit_exponent=True)
    out.append((s, s.from_physical(Fc=20.0, Fs=35.0, vs=4e-3, sigma2=150.0, delta=1.3)))
    # §13.1 asymmetric / offset forms (every _pos level differs from its _neg) and GMS (§8.4)
    ca = models.Coulomb(asymmetric=True, offset=True)
    out.append((ca, ca.from_physical(Fc_pos=20.0, Fc_neg=12.0, sigma2_pos=200.0, sigma2_neg=120.0, F_off=3.0)))
    sa = models.Stribeck(asymmetric=True, offset=True)
    out.append((sa, sa.from_physical(Fc_pos=20.0, Fc_neg=14.0, Fs_pos=35.0, Fs_neg=22.0, vs=4e-3,
                                     sigma2_pos=150.0, sigma2_neg=90.0, F_off=-2.0)))
    so = models.Stribeck(offset=True)
    out.append((so, so.from_physical(Fc=20.0, Fs=35.0, vs=4e-3, sigma2=150.0, F_off=1.5)))
    la = models.LuGre(asymmetric=True, offset=True)
    out.append((la, la.from_physical(sigma0=1e6, sigma1=300.0, sigma2_pos=500.0, sigma2_neg=350.0,
                                     Fc_pos=20.0, Fc_neg=14.0, Fs_pos=30.0, Fs_neg=25.0, vs=5e-3, F_off=-3.0)))
    da = models.Dahl(viscous=True, asymmetric=True, offset=True)
    out.append((da, da.from_physical(sigma0=2e5, Fc_pos=15.0, Fc_neg=9.0, sigma2_pos=100.0,
                                     sigma2_neg=60.0, F_off=2.5)))
    do = models.Dahl(offset=True)
    out.append((do, do.from_physical(sigma0=2e5, Fc=15.0, F_off=-1.5)))
    gms = dict(k1=2e5, k2=6e4, k3=1e4, alpha1=0.5, alpha2=0.3, alpha3=0.2, C=30.0, vs=4e-3)
    g = models.GMS(num_elements=3)
    out.append((g, g.from_physical(Fc=20.0, Fs=30.0, sigma2=150.0, **gms)))
    ga = models.GMS(num_elements=3, asymmetric=True, offset=True)
    out.append((ga, ga.from_physical(Fc_pos=20.0, Fc_neg=13.0, Fs_pos=30.0, Fs_neg=22.0, sigma2_pos=150.0,
                                     sigma2_neg=90.0, F_off=4.0, **gms)))
    return out


def _id(x):
    if not isinstance(x, models.AbstractFrictionModel):
        return "theta"
    return type(x).__name__ + "".join(f"-{f}" for f in ("asymmetric", "offset") if getattr(x, f, False))


def _close(got, ref):
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-6 * np.max(np.abs(ref)))


@pytest.mark.parametrize("model,theta", _cases(), ids=_id)
def test_numpy_step_matches_predict(model, theta):
    v = _velocity()
    with jax.enable_x64(True):
        fit = _fit(model, theta, v)
        ref = np.asarray(fit.predict(v))
    step = fit.to_numpy()
    _close(step.run(v), ref)
    f0, s = step.step(v[0], None)  # the documented call form
    assert f0 == pytest.approx(ref[0], rel=1e-6)


_CC = shutil.which("cc") or shutil.which("gcc")

_HARNESS = r"""
#include <stdio.h>
#include "friction.h"
int main(void) {
    double v; jaxfric_state s; int first = 1;
    while (scanf("%lf", &v) == 1) {
        if (first) { jaxfric_init(&s, v); first = 0; }
        printf("%.17g\n", jaxfric_step(&s, v));
    }
    return 0;
}
"""


@pytest.mark.skipif(_CC is None, reason="no C compiler (cc/gcc) on this machine")
@pytest.mark.parametrize("model,theta", _cases(), ids=_id)
def test_c_header_matches_predict(model, theta, tmp_path):
    v = _velocity()
    with jax.enable_x64(True):
        fit = _fit(model, theta, v)
        ref = np.asarray(fit.predict(v))
    fit.to_c_header(tmp_path / "friction.h")
    (tmp_path / "main.c").write_text(_HARNESS)
    exe = tmp_path / "run"
    subprocess.run([_CC, "-std=c99", "-O2", "-Wall", "-Werror", "-o", str(exe), str(tmp_path / "main.c"),
                    "-lm"], check=True, cwd=tmp_path, capture_output=True)
    out = subprocess.run([str(exe)], input="\n".join(repr(float(x)) for x in v), text=True,
                         capture_output=True, check=True).stdout
    _close(np.array(out.split(), float), ref)


def test_export_refuses_unknown_prefix_and_model():
    from jaxfric.export import c_header

    v = _velocity(50)
    fit = _fit(models.Coulomb(), models.Coulomb().from_physical(Fc=1.0, sigma2=1.0), v)
    with pytest.raises(ValueError, match="identifier"):
        c_header(fit, prefix="bad name")
    cyl = models.Cylinder()
    lo, hi = cyl.bounds()
    bad = _fit(cyl, 0.5 * (np.asarray(lo) + np.asarray(hi)), v)
    with pytest.raises(ValueError, match="Cylinder.*pressure"):
        bad.to_numpy()
    with pytest.raises(ValueError, match="Cylinder.*pressure"):
        c_header(bad)


def test_motion_fit_export_includes_its_offset(tmp_path):
    """A MotionFit's friction includes its fitted constant offset; so do both exports."""
    from jaxfric.motion import MotionFit

    v = _velocity()  # the record of the tests above, whose LuGre programs it reuses
    lugre = models.LuGre()
    theta = lugre.from_physical(sigma0=1e6, sigma1=300.0, sigma2=500.0, Fc=20.0, Fs=30.0, vs=5e-3)
    fit = MotionFit.given(lugre, theta, mass=1.0, offset=-3.25, dt=1e-3, n_train=10, n_samples=10)
    with jax.enable_x64(True):
        ref = np.asarray(fit.predict(v))
        plain = np.asarray(Fit.predict(fit, v))
    np.testing.assert_allclose(ref - plain, -3.25)
    _close(fit.to_numpy().run(v), ref)
    if _CC is not None:
        fit.to_c_header(tmp_path / "friction.h")
        (tmp_path / "main.c").write_text(_HARNESS)
        subprocess.run([_CC, "-std=c99", "-O2", "-Wall", "-Werror", "-o", str(tmp_path / "run"),
                        str(tmp_path / "main.c"), "-lm"], check=True, cwd=tmp_path, capture_output=True)
        out = subprocess.run([str(tmp_path / "run")], input="\n".join(repr(float(x)) for x in v), text=True,
                             capture_output=True, check=True).stdout
        _close(np.array(out.split(), float), ref)
