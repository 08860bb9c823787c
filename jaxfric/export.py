"""A fitted friction model outside JAX: a pure-NumPy step function and a C header.

For a controller's real-time loop the free-run rollout of :meth:`jaxfric.Fit.predict`
is split into one call per sample (the per-sample form of ``jaxfric.motion``):

    f, state = step(v, state)        F_k = output(s_k, v_k),  s_{k+1} = update(s_k, v_k)

with ``state = None`` on the first call (the model then starts as ``Fit.predict``
does: LuGre/Dahl from the steady state at the first velocity, docs/algorithms.md §8.1;
the Elman networks from their learned context ``c0``, §2.2). Velocity in m/s,
friction in N; the §2.4 scalers of the Elman networks are applied inside.

* :func:`numpy_step` (``Fit.to_numpy()``): a :class:`NumpyStep` holding the weights as
  float64 NumPy arrays;
* :func:`c_header` (``Fit.to_c_header(path)``): C99 source of the same step with the
  weights as ``static const double`` arrays, for ``#include`` in a controller::

      jaxfric_state s;  jaxfric_init(&s, v0);
      double f = jaxfric_step(&s, v);      /* every sample */

Both reproduce ``Fit.predict`` to rounding (``tests/test_export.py`` compiles the
header with the system C compiler and compares on a recording). Supported: Elman,
ElmanFull, LuGre, Dahl, Coulomb, Stribeck.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re

import numpy as np

from .models import Coulomb, Dahl, Elman, ElmanFull, LuGre, Stribeck

__all__ = ["NumpyStep", "c_header", "numpy_step"]

_SUPPORTED = (Elman, ElmanFull, LuGre, Dahl, Coulomb, Stribeck)


def _kind(model) -> str:
    for cls, name in ((Elman, "elman"), (ElmanFull, "elman_full"), (LuGre, "lugre"),
                      (Dahl, "dahl"), (Coulomb, "coulomb"), (Stribeck, "stribeck")):
        if type(model) is cls:
            return name
    raise ValueError(f"export supports {', '.join(c.__name__ for c in _SUPPORTED)}; "
                     f"got {type(model).__name__}")


def _weights(fit) -> dict:
    """The fit's parameters as float64 NumPy (physical units, or the networks' blocks)
    plus the scalers and the model's fixed hyperparameters."""
    import jax.numpy as jnp

    model = fit.model
    kind = _kind(model)
    p = {k: np.asarray(v, np.float64) for k, v in
         model.to_physical(jnp.asarray(np.asarray(fit.theta, np.float64))).items()}
    # a MotionFit's constant force offset is part of its friction (MotionFit.predict)
    w = {"kind": kind, **p, "offset": float(getattr(fit, "offset", 0.0))}
    if model.needs_scaling:
        w.update(v_lo=float(fit.velocity_scaler.lo), v_hi=float(fit.velocity_scaler.hi),
                 f_lo=float(fit.friction_scaler.lo), f_hi=float(fit.friction_scaler.hi))
    if kind == "elman":
        w["b_o"] = float(p["b_o"]) if model.output_bias else 0.0
    if kind == "elman_full":
        w["b_o"] = float(p["b_o"]) if model.output_bias else 0.0
        w["c0"] = p["c0"] if model.learn_c0 else np.zeros_like(p["w"])
    if kind == "lugre":
        w["delta"] = float(model.stribeck_exponent)
    if kind == "dahl":
        w["sigma2"] = float(p["sigma2"]) if model.viscous else 0.0
    if kind == "coulomb":
        w["v_eps"] = float(model.v_eps)
        w["sigma2"] = float(p["sigma2"]) if model.viscous else 0.0
    if kind == "stribeck":
        w["v_eps"] = float(model.v_eps)
        w["delta"] = float(p["delta"]) if model.fit_exponent else float(model.exponent)
    return w


def _stribeck(v, fc, fs, vs, delta):
    r = abs(v) / vs
    return fc + (fs - fc) * math.exp(-(r * r if delta == 2.0 else r ** delta))


def _phi(x):
    return 1.0 - 0.5 * x if x < 1e-8 else -math.expm1(-x) / x


@dataclasses.dataclass(frozen=True)
class NumpyStep:
    """Pure-NumPy per-sample friction of a fit (module docstring).

    ``step(v, state) -> (f, state)``; ``init(v0)`` gives the initial state (also used
    when ``state`` is ``None``); ``dt`` [s] is the sample time the fit was made at
    (bristle models integrate with it); ``weights`` the parameters used.
    """

    weights: dict
    dt: float

    def init(self, v0: float = 0.0):
        w, v0 = self.weights, float(v0)
        kind = w["kind"]
        if kind == "lugre":
            g = _stribeck(v0, w["Fc"], w["Fs"], w["vs"], w["delta"])
            return np.sign(v0) * g / w["sigma0"]
        if kind == "dahl":
            return np.sign(v0) * w["Fc"] / w["sigma0"]
        if kind in ("elman", "elman_full"):
            return np.array(w["c0"], np.float64)
        return None

    def step(self, v: float, state=None):
        f, state = self._step(float(v), state)
        return f + self.weights["offset"], state

    def _step(self, v: float, state):
        w = self.weights
        if state is None:
            state = self.init(v)
        kind = w["kind"]
        if kind in ("lugre", "dahl"):
            s0, s2 = w["sigma0"], w["sigma2"]
            if kind == "lugre":
                s1, g = w["sigma1"], _stribeck(v, w["Fc"], w["Fs"], w["vs"], w["delta"])
            else:
                s1, g = 0.0, w["Fc"]
            a = s0 * abs(v) / g
            f = s0 * state + s1 * (v - a * state) + s2 * v
            x = a * self.dt
            return float(f), float(state * math.exp(-x) + v * self.dt * _phi(x))
        if kind == "coulomb":
            return float(w["Fc"] * math.tanh(v / w["v_eps"]) + w["sigma2"] * v), None
        if kind == "stribeck":
            g = _stribeck(v, w["Fc"], w["Fs"], w["vs"], w["delta"])
            return float(math.tanh(v / w["v_eps"]) * g + w["sigma2"] * v), None
        u = 2.0 * (v - w["v_lo"]) / (w["v_hi"] - w["v_lo"]) - 1.0
        if kind == "elman":
            h = np.tanh(w["w"] * u + w["r"] * state + w["b"])
            new = w["alpha"] * state + h
        else:
            h = np.tanh(w["w"] * u + w["W_c"] @ state + w["b"])
            new = h
        y = float(w["v"] @ h) + w["b_o"]
        return float((y + 1.0) * (0.5 * (w["f_hi"] - w["f_lo"])) + w["f_lo"]), new

    def run(self, velocity) -> np.ndarray:
        """Friction [N] for a whole velocity record, one :meth:`step` per sample."""
        state, out = None, []
        for v in np.asarray(velocity, np.float64).ravel():
            f, state = self.step(v, state)
            out.append(f)
        return np.asarray(out)


def numpy_step(fit) -> NumpyStep:
    """:class:`NumpyStep` of ``fit`` (a :class:`jaxfric.Fit`; module docstring)."""
    return NumpyStep(_weights(fit), float(fit.dt))


# ---------------------------------------------------------------------------- C
def _num(x: float) -> str:
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot export a non-finite weight ({x})")
    return repr(x)


def _array(name: str, values) -> str:
    vals = np.asarray(values, np.float64).ravel()
    body = ",\n    ".join(", ".join(_num(v) for v in vals[i:i + 4]) for i in range(0, vals.size, 4))
    return f"static const double {name}[{vals.size}] = {{\n    {body}\n}};"


def c_header(fit, path=None, *, prefix: str = "jaxfric") -> str:
    """C99 header with the per-sample friction of ``fit`` and its weights (module docstring).

    Defines ``<prefix>_state``, ``<prefix>_init(state*, v0)`` and
    ``double <prefix>_step(state*, v)`` (v in m/s, returns N), all ``static inline``;
    needs ``<math.h>`` (link with ``-lm``). Returns the source; writes it to ``path``
    if given.
    """
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", prefix):
        raise ValueError(f"prefix must be a C identifier, got {prefix!r}")
    w, dt = _weights(fit), float(fit.dt)
    P, kind = prefix, w["kind"]
    guard = f"{P.upper()}_FRICTION_H"
    lines = [f"/* Generated by jaxfric.export from a {type(fit.model).__name__} fit: per-sample friction",
             " * F_k = output(s_k, v_k), s_{k+1} = update(s_k, v_k), as Fit.predict. v [m/s], F [N]. */",
             f"#ifndef {guard}", f"#define {guard}", "#include <math.h>", ""]
    stribeck = (f"static inline double {P}_g(double v, double fc, double fs, double vs, double delta) {{\n"
                f"    double r = fabs(v) / vs;\n"
                f"    return fc + (fs - fc) * exp(-(delta == 2.0 ? r * r : pow(r, delta)));\n}}\n")
    if kind in ("lugre", "dahl"):
        lines.append(f"typedef struct {{ double z; }} {P}_state;")
        lines.append(f"static const double {P}_dt = {_num(dt)};")
        s1 = w["sigma1"] if kind == "lugre" else 0.0
        for name, val in (("sigma0", w["sigma0"]), ("sigma1", s1), ("sigma2", w["sigma2"]), ("Fc", w["Fc"])):
            lines.append(f"static const double {P}_{name} = {_num(val)};")
        if kind == "lugre":
            for name in ("Fs", "vs", "delta"):
                lines.append(f"static const double {P}_{name} = {_num(w[name])};")
            lines.append(stribeck)
            g = f"{P}_g(v, {P}_Fc, {P}_Fs, {P}_vs, {P}_delta)"
        else:
            g = f"{P}_Fc"
        sign = "((v > 0) - (v < 0))"
        lines.append(f"static inline void {P}_init({P}_state *s, double v) {{ s->z = {sign} * {g} / {P}_sigma0; }}")
        lines.append(
            f"static inline double {P}_step({P}_state *s, double v) {{\n"
            f"    double g = {g};\n"
            f"    double a = {P}_sigma0 * fabs(v) / g;\n"
            f"    double f = {P}_sigma0 * s->z + {P}_sigma1 * (v - a * s->z) + {P}_sigma2 * v;\n"
            f"    double x = a * {P}_dt;\n"
            f"    double phi = x < 1e-8 ? 1.0 - 0.5 * x : -expm1(-x) / x;\n"
            f"    s->z = s->z * exp(-x) + v * {P}_dt * phi;\n"
            f"    return f;\n}}")
    elif kind in ("coulomb", "stribeck"):
        lines.append(f"typedef struct {{ int unused; }} {P}_state;")
        lines.append(f"static inline void {P}_init({P}_state *s, double v) {{ (void)s; (void)v; }}")
        for name in ("Fc", "sigma2", "v_eps") + (("Fs", "vs", "delta") if kind == "stribeck" else ()):
            lines.append(f"static const double {P}_{name} = {_num(w[name])};")
        if kind == "stribeck":
            lines.append(stribeck)
            level = f"{P}_g(v, {P}_Fc, {P}_Fs, {P}_vs, {P}_delta)"
        else:
            level = f"{P}_Fc"
        lines.append(f"static inline double {P}_step({P}_state *s, double v) {{\n    (void)s;\n"
                     f"    return tanh(v / {P}_v_eps) * {level} + {P}_sigma2 * v;\n}}")
    else:
        n = int(np.asarray(w["w"]).size)
        lines.append(f"#define {P.upper()}_N {n}")
        lines.append(f"typedef struct {{ double c[{n}]; }} {P}_state;")
        blocks = ("w", "b", "v", "c0") + (("r", "alpha") if kind == "elman" else ("W_c",))
        for name in blocks:
            lines.append(_array(f"{P}_{name}", w[name]))
        for name in ("b_o", "v_lo", "v_hi", "f_lo", "f_hi"):
            lines.append(f"static const double {P}_{name} = {_num(w[name])};")
        lines.append(f"static inline void {P}_init({P}_state *s, double v) {{\n    (void)v;\n"
                     f"    for (int j = 0; j < {n}; ++j) s->c[j] = {P}_c0[j];\n}}")
        if kind == "elman":
            pre = f"{P}_w[j] * u + {P}_r[j] * s->c[j] + {P}_b[j]"
            hidden = (f"    for (int j = 0; j < {n}; ++j) {{\n"
                      f"        double h = tanh({pre});\n"
                      f"        y += {P}_v[j] * h;\n"
                      f"        s->c[j] = {P}_alpha[j] * s->c[j] + h;\n    }}\n")
        else:
            hidden = (f"    double h[{n}];\n"
                      f"    for (int i = 0; i < {n}; ++i) {{\n"
                      f"        double a = {P}_w[i] * u + {P}_b[i];\n"
                      f"        for (int j = 0; j < {n}; ++j) a += {P}_W_c[i * {n} + j] * s->c[j];\n"
                      f"        h[i] = tanh(a);\n"
                      f"        y += {P}_v[i] * h[i];\n    }}\n"
                      f"    for (int i = 0; i < {n}; ++i) s->c[i] = h[i];\n")
        lines.append(
            f"static inline double {P}_step({P}_state *s, double v) {{\n"
            f"    double u = 2.0 * (v - {P}_v_lo) / ({P}_v_hi - {P}_v_lo) - 1.0;\n"
            f"    double y = 0.0;\n{hidden}"
            f"    y += {P}_b_o;\n"
            f"    return (y + 1.0) * (0.5 * ({P}_f_hi - {P}_f_lo)) + {P}_f_lo;\n}}")
    # every model's step above is <prefix>_core; the public step adds the offset
    text = "\n".join(lines)
    text = text.replace(f"static inline double {P}_step(", f"static inline double {P}_core(")
    lines = [text, f"static const double {P}_offset = {_num(w['offset'])};",
             f"static inline double {P}_step({P}_state *s, double v) {{ return {P}_core(s, v) + {P}_offset; }}",
             "", f"#endif /* {guard} */", ""]
    text = "\n".join(lines)
    if path is not None:
        from .report import atomic_write_text

        atomic_write_text(os.fspath(path), text)
    return text
