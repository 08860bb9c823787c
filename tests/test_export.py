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
    return out


def _close(got, ref):
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-6 * np.max(np.abs(ref)))


@pytest.mark.parametrize("model,theta", _cases(), ids=lambda x: type(x).__name__)
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
@pytest.mark.parametrize("model,theta", _cases(), ids=lambda x: type(x).__name__)
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


def test_motion_fit_export_includes_its_offset(tmp_path):
    """A MotionFit's friction includes its fitted constant offset; so do both exports."""
    from jaxfric.motion import MotionFit

    v = _velocity(300)
    lugre = models.LuGre()
    theta = lugre.from_physical(sigma0=1e6, sigma1=300.0, sigma2=500.0, Fc=20.0, Fs=30.0, vs=5e-3)
    fit = MotionFit(model=lugre, theta=np.asarray(theta, np.float64), velocity_scaler=None,
                    friction_scaler=None, dt=1e-3, n_train=10, n_samples=10, metrics={},
                    settings={"motion": {"mass": 1.0, "offset": -3.25, "v0": 0.0}})
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
