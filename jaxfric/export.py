"""A fitted friction model outside JAX: a pure-NumPy step function and a C header.

For a controller's real-time loop the free-run rollout of [`jaxfric.Fit.predict`][jaxfric.fit.Fit.predict]
is split into one call per sample (the per-sample form of [`jaxfric.motion`][jaxfric.motion]):

    f, state = step(v, state)        F_k = output(s_k, v_k),  s_{k+1} = update(s_k, v_k)

with ``state = None`` on the first call (the model then starts as ``Fit.predict``
does: LuGre/Dahl from the steady state at the first velocity, docs/algorithms.md §8.1;
the Elman networks from their learned context ``c0``, §2.2). Velocity in m/s,
friction in N; the §2.4 scalers of the Elman networks are applied inside.

* [`numpy_step`][jaxfric.export.numpy_step] (``Fit.to_numpy()``): a [`NumpyStep`][jaxfric.export.NumpyStep] holding the weights as
  float64 NumPy arrays;
* [`c_header`][jaxfric.export.c_header] (``Fit.to_c_header(path)``): C99 source of the same step with the
  weights as ``static const double`` arrays, for ``#include`` in a controller::

      jaxfric_state s;  jaxfric_init(&s, v0);
      double f = jaxfric_step(&s, v);      /* every sample */

Both reproduce ``Fit.predict`` to rounding (``tests/test_export.py`` compiles the
header with the system C compiler and compares on a recording). Supported: Elman,
ElmanFull, LuGre, Dahl, Coulomb, Stribeck (symmetric or in the docs/algorithms.md §13.1
``asymmetric`` / ``offset`` forms) and GMS (§8.4, either form). A symmetric model is
exported as the asymmetric form with equal ``_pos`` / ``_neg`` levels, which is the same
arithmetic (``max(t, 0) L - max(-t, 0) L = t L``); the model's ``F_off`` joins the
fit's constant offset. ``Cylinder`` is refused: its friction needs the chamber
pressures as a second input, which a ``step(v, state)`` does not carry.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re

import numpy as np

from .models import GMS, Coulomb, Cylinder, Dahl, Elman, ElmanFull, LuGre, Stribeck

__all__ = ["NumpyStep", "c_header", "numpy_step"]

_SUPPORTED = (Elman, ElmanFull, LuGre, Dahl, Coulomb, Stribeck, GMS)
#: direction-dependent levels (§13.1); a symmetric model's one value fills both
_DIRECTIONAL = ("Fc", "Fs", "sigma2")


def _kind(model) -> str:
    for cls, name in ((Elman, "elman"), (ElmanFull, "elman_full"), (LuGre, "lugre"),
                      (Dahl, "dahl"), (Coulomb, "coulomb"), (Stribeck, "stribeck"), (GMS, "gms")):
        if type(model) is cls:
            return name
    if isinstance(model, Cylinder):
        raise ValueError("export does not support Cylinder: its friction depends on the chamber "
                         "pressures, a second input that step(v, state) does not carry")
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
    if kind in ("elman", "elman_full"):
        w["b_o"] = float(p["b_o"]) if model.output_bias else 0.0
    if kind == "elman_full":
        w["c0"] = p["c0"] if model.learn_c0 else np.zeros_like(p["w"])
    if kind == "lugre":
        w["delta"] = float(model.stribeck_exponent)
    if kind in ("dahl", "coulomb") and not model.viscous:
        w["sigma2"] = 0.0
    if kind in ("coulomb", "stribeck"):
        w["v_eps"] = float(model.v_eps)
    if kind == "stribeck":
        w["delta"] = float(p["delta"]) if model.fit_exponent else float(model.exponent)
    if kind == "gms":
        n = model.num_elements
        w["k"] = np.array([p[f"k{i}"] for i in range(1, n + 1)], np.float64)
        w["alpha"] = np.array([p[f"alpha{i}"] for i in range(1, n + 1)], np.float64)
        w["delta"] = float(model.stribeck_exponent)
    for name in _DIRECTIONAL:
        if name in w:
            w[name + "_pos"] = w[name + "_neg"] = float(w.pop(name))
    # the model's own output offset (§13.1) is one more constant force
    w["offset"] += float(w.pop("F_off", 0.0))
    return w


def _pick(w, name, v):
    """The §13.1 level ``name`` acting at velocity v: ``_pos`` for v > 0, else ``_neg``."""
    return w[name + "_pos"] if v > 0 else w[name + "_neg"]


def _slip_level(w, v):
    """Stribeck level g(v) / s(v) of the direction v moves in (LuGre, Stribeck, GMS)."""
    return _stribeck(v, _pick(w, "Fc", v), _pick(w, "Fs", v), w["vs"], w["delta"])


def _stribeck(v, fc, fs, vs, delta):
    r = abs(v) / vs
    return fc + (fs - fc) * math.exp(-(r * r if delta == 2.0 else r ** delta))


def _phi(x):
    return 1.0 - 0.5 * x if x < 1e-8 else -math.expm1(-x) / x


def _elman_hidden(w, u, c):
    """The Elman networks' hidden layer in NumPy: ``tanh(w u + r c + b)`` (§2.2) or
    ``tanh(w u + W_c c + b)`` (§2.3). The one home of each recurrence is
    ``jaxfric.models.elman_hidden`` / ``elman_full_hidden``; this is their deliberate twin,
    as is the C of [`c_header`][jaxfric.export.c_header]: an exported step computes without JAX
    (in a controller's loop, one float64 sample at a time, with NumPy or a C compiler
    alone), and ``tests/test_export.py`` holds both twins to ``Fit.predict``."""
    if "W_c" in w:
        return np.tanh(w["w"] * u + w["W_c"] @ c + w["b"])
    return np.tanh(w["w"] * u + w["r"] * c + w["b"])


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
            return np.sign(v0) * _slip_level(w, v0) / w["sigma0"]
        if kind == "dahl":
            return np.sign(v0) * _pick(w, "Fc", v0) / w["sigma0"]
        if kind == "gms":
            force = w["alpha"] * (_slip_level(w, v0) * np.sign(v0))
            return force, np.full_like(force, np.sign(v0))
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
            s0, s2 = w["sigma0"], _pick(w, "sigma2", v)
            if kind == "lugre":
                s1, g = w["sigma1"], _slip_level(w, v)
            else:
                s1, g = 0.0, _pick(w, "Fc", v)
            a = s0 * abs(v) / g
            f = s0 * state + s1 * (v - a * state) + s2 * v
            x = a * self.dt
            return float(f), float(state * math.exp(-x) + v * self.dt * _phi(x))
        if kind == "gms":
            return self._gms(v, state)
        if kind in ("coulomb", "stribeck"):
            t = math.tanh(v / w["v_eps"])
            if kind == "coulomb":
                pos, neg = w["Fc_pos"], w["Fc_neg"]
            else:
                pos = _stribeck(v, w["Fc_pos"], w["Fs_pos"], w["vs"], w["delta"])
                neg = _stribeck(v, w["Fc_neg"], w["Fs_neg"], w["vs"], w["delta"])
            level = max(t, 0.0) * pos - max(-t, 0.0) * neg
            return float(level + _pick(w, "sigma2", v) * v), None
        u = 2.0 * (v - w["v_lo"]) / (w["v_hi"] - w["v_lo"]) - 1.0
        h = _elman_hidden(w, u, state)
        new = w["alpha"] * state + h if kind == "elman" else h
        y = float(w["v"] @ h) + w["b_o"]
        return float((y + 1.0) * (0.5 * (w["f_hi"] - w["f_lo"])) + w["f_lo"]), new

    def _gms(self, v, state):
        """§8.4 element update over one held sample (``jaxfric.models.gms``)."""
        w = self.weights
        force, direction = state
        f = float(np.sum(force)) + _pick(w, "sigma2", v) * v
        s = _slip_level(w, v)
        sv = float(np.sign(v))
        level = w["alpha"] * s
        target = level * sv
        relaxed = target + (force - target) * math.exp(-w["C"] * self.dt / s)
        stuck = force + w["k"] * (v * self.dt)
        moving = sv != 0.0
        slips = moving & ((direction == sv) | (sv * force >= level))
        reaches = moving & (sv * stuck >= level)
        new_force = np.where(slips, relaxed, np.where(reaches, target, stuck))
        new_direction = np.where(slips | reaches, sv, 0.0)
        return float(f), (new_force, new_direction)

    def run(self, velocity) -> np.ndarray:
        """Friction [N] for a whole velocity record, one [`step`][jaxfric.export.NumpyStep.step] per sample."""
        state, out = None, []
        for v in np.asarray(velocity, np.float64).ravel():
            f, state = self.step(v, state)
            out.append(f)
        return np.asarray(out)


def numpy_step(fit) -> NumpyStep:
    """[`NumpyStep`][jaxfric.export.NumpyStep] of ``fit`` (a [`jaxfric.Fit`][jaxfric.fit.Fit]; module docstring)."""
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


class _CText:
    """The C spellings of one fit's weights, prefixed ``P``: constants, the §13.1 level of
    the direction ``v`` moves in, the Stribeck curve ``P_g`` and the velocity's sign."""

    def __init__(self, P: str, w: dict):
        self.P, self.w = P, w
        self.sign = "((v > 0) - (v < 0))"
        self.slip = (f"(v > 0 ? {P}_g(v, {P}_Fc_pos, {P}_Fs_pos, {P}_vs, {P}_delta)"
                     f" : {P}_g(v, {P}_Fc_neg, {P}_Fs_neg, {P}_vs, {P}_delta))")
        self.stribeck = (f"static inline double {P}_g(double v, double fc, double fs, double vs, double delta) {{\n"
                         f"    double r = fabs(v) / vs;\n"
                         f"    return fc + (fs - fc) * exp(-(delta == 2.0 ? r * r : pow(r, delta)));\n}}\n")

    def lvl(self, name: str) -> str:
        return f"(v > 0 ? {self.P}_{name}_pos : {self.P}_{name}_neg)"

    def consts(self, names) -> list[str]:
        return [f"static const double {self.P}_{name}{sfx} = {_num(self.w[name + sfx])};"
                for name in names for sfx in (("_pos", "_neg") if name in _DIRECTIONAL else ("",))]


def _c_bristle(c: _CText, w: dict, dt: float) -> list[str]:
    """LuGre / Dahl: the exact zero-order-hold update of §8.2."""
    P, lugre = c.P, w["kind"] == "lugre"
    lines = [f"typedef struct {{ double z; }} {P}_state;", f"static const double {P}_dt = {_num(dt)};",
             f"static const double {P}_sigma1 = {_num(w['sigma1'] if lugre else 0.0)};"]
    lines += c.consts(("sigma0", "sigma2", "Fc") + (("Fs", "vs", "delta") if lugre else ()))
    if lugre:
        lines.append(c.stribeck)
    g = c.slip if lugre else c.lvl("Fc")
    return lines + [
        f"static inline void {P}_init({P}_state *s, double v) {{ s->z = {c.sign} * {g} / {P}_sigma0; }}",
        f"static inline double {P}_step({P}_state *s, double v) {{\n"
        f"    double g = {g};\n"
        f"    double a = {P}_sigma0 * fabs(v) / g;\n"
        f"    double f = {P}_sigma0 * s->z + {P}_sigma1 * (v - a * s->z) + {c.lvl('sigma2')} * v;\n"
        f"    double x = a * {P}_dt;\n"
        f"    double phi = x < 1e-8 ? 1.0 - 0.5 * x : -expm1(-x) / x;\n"
        f"    s->z = s->z * exp(-x) + v * {P}_dt * phi;\n"
        f"    return f;\n}}"]


def _c_gms(c: _CText, w: dict, dt: float) -> list[str]:
    """GMS: the element update of §8.4 over one held sample."""
    P, n = c.P, int(w["k"].size)
    return [f"#define {P.upper()}_N {n}", f"typedef struct {{ double F[{n}]; double d[{n}]; }} {P}_state;",
            f"static const double {P}_dt = {_num(dt)};", _array(f"{P}_k", w["k"]), _array(f"{P}_alpha", w["alpha"]),
            *c.consts(("C", "Fc", "Fs", "vs", "delta", "sigma2")), c.stribeck,
            f"static inline void {P}_init({P}_state *s, double v) {{\n"
            f"    double sg = {c.sign}, lv = {c.slip};\n"
            f"    for (int j = 0; j < {n}; ++j) {{ s->F[j] = {P}_alpha[j] * (lv * sg); s->d[j] = sg; }}\n}}",
            f"static inline double {P}_step({P}_state *s, double v) {{\n"
            f"    double f = 0.0;\n"
            f"    for (int j = 0; j < {n}; ++j) f += s->F[j];\n"
            f"    f += {c.lvl('sigma2')} * v;\n"
            f"    double lv = {c.slip}, sv = {c.sign};\n"
            f"    double decay = exp(-{P}_C * {P}_dt / lv);\n"
            f"    for (int j = 0; j < {n}; ++j) {{\n"
            f"        double level = {P}_alpha[j] * lv, target = level * sv;\n"
            f"        double relaxed = target + (s->F[j] - target) * decay;\n"
            f"        double stuck = s->F[j] + {P}_k[j] * (v * {P}_dt);\n"
            f"        int moving = sv != 0.0;\n"
            f"        int slips = moving && (s->d[j] == sv || sv * s->F[j] >= level);\n"
            f"        int reaches = moving && sv * stuck >= level;\n"
            f"        s->F[j] = slips ? relaxed : (reaches ? target : stuck);\n"
            f"        s->d[j] = (slips || reaches) ? sv : 0.0;\n"
            f"    }}\n"
            f"    return f;\n}}"]


def _c_static(c: _CText, w: dict, dt: float) -> list[str]:
    """Coulomb / Stribeck: a static map of the velocity (no state)."""
    P, stribeck = c.P, w["kind"] == "stribeck"
    lines = [f"typedef struct {{ int unused; }} {P}_state;",
             f"static inline void {P}_init({P}_state *s, double v) {{ (void)s; (void)v; }}",
             *c.consts(("Fc", "sigma2", "v_eps") + (("Fs", "vs", "delta") if stribeck else ()))]
    if stribeck:
        lines.append(c.stribeck)
        pos = f"{P}_g(v, {P}_Fc_pos, {P}_Fs_pos, {P}_vs, {P}_delta)"
        neg = f"{P}_g(v, {P}_Fc_neg, {P}_Fs_neg, {P}_vs, {P}_delta)"
    else:
        pos, neg = f"{P}_Fc_pos", f"{P}_Fc_neg"
    return lines + [f"static inline double {P}_step({P}_state *s, double v) {{\n    (void)s;\n"
                    f"    double t = tanh(v / {P}_v_eps);\n"
                    f"    return fmax(t, 0.0) * {pos} - fmax(-t, 0.0) * {neg} + {c.lvl('sigma2')} * v;\n}}"]


def _c_elman(c: _CText, w: dict, dt: float) -> list[str]:
    """Elman / ElmanFull (§2.2, §2.3) with the §2.4 scalers: the C twin of the hidden
    layer (`_elman_hidden` says why export keeps twins)."""
    P, n, elman = c.P, int(np.asarray(w["w"]).size), w["kind"] == "elman"
    blocks = ("w", "b", "v", "c0") + (("r", "alpha") if elman else ("W_c",))
    lines = [f"#define {P.upper()}_N {n}", f"typedef struct {{ double c[{n}]; }} {P}_state;",
             *(_array(f"{P}_{name}", w[name]) for name in blocks),
             *(f"static const double {P}_{name} = {_num(w[name])};" for name in ("b_o", "v_lo", "v_hi", "f_lo", "f_hi")),
             f"static inline void {P}_init({P}_state *s, double v) {{\n    (void)v;\n"
             f"    for (int j = 0; j < {n}; ++j) s->c[j] = {P}_c0[j];\n}}"]
    if elman:
        hidden = (f"    for (int j = 0; j < {n}; ++j) {{\n"
                  f"        double h = tanh({P}_w[j] * u + {P}_r[j] * s->c[j] + {P}_b[j]);\n"
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
    return lines + [f"static inline double {P}_step({P}_state *s, double v) {{\n"
                    f"    double u = 2.0 * (v - {P}_v_lo) / ({P}_v_hi - {P}_v_lo) - 1.0;\n"
                    f"    double y = 0.0;\n{hidden}"
                    f"    y += {P}_b_o;\n"
                    f"    return (y + 1.0) * (0.5 * ({P}_f_hi - {P}_f_lo)) + {P}_f_lo;\n}}"]


_C_BODIES = {"lugre": _c_bristle, "dahl": _c_bristle, "gms": _c_gms, "coulomb": _c_static,
             "stribeck": _c_static, "elman": _c_elman, "elman_full": _c_elman}


def c_header(fit, path=None, *, prefix: str = "jaxfric") -> str:
    """C99 header with the per-sample friction of ``fit`` and its weights (module docstring).

    Defines ``<prefix>_state``, ``<prefix>_init(state*, v0)`` and
    ``double <prefix>_step(state*, v)`` (v in m/s, returns N), all ``static inline``;
    needs ``<math.h>`` (link with ``-lm``). Returns the source; writes it to ``path``
    if given.
    """
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", prefix):
        raise ValueError(f"prefix must be a C identifier, got {prefix!r}")
    w, P = _weights(fit), prefix
    guard = f"{P.upper()}_FRICTION_H"
    lines = [f"/* Generated by jaxfric.export from a {type(fit.model).__name__} fit: per-sample friction",
             " * F_k = output(s_k, v_k), s_{k+1} = update(s_k, v_k), as Fit.predict. v [m/s], F [N]. */",
             f"#ifndef {guard}", f"#define {guard}", "#include <math.h>", ""]
    lines += _C_BODIES[w["kind"]](_CText(P, w), w, float(fit.dt))
    # every model's step above is <prefix>_core; the public step adds the offset
    text = "\n".join(lines).replace(f"static inline double {P}_step(", f"static inline double {P}_core(")
    text = "\n".join([text, f"static const double {P}_offset = {_num(w['offset'])};",
                      f"static inline double {P}_step({P}_state *s, double v) {{ return {P}_core(s, v) + {P}_offset; }}",
                      "", f"#endif /* {guard} */", ""])
    if path is not None:
        from .files import atomic_write_text

        atomic_write_text(os.fspath(path), text)
    return text
