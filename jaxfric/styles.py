"""One look per model family and per solver, shared by every figure of jaxfric (the report,
the compensation study, the notebooks): plain data and a lookup, no plotting, so that
modules below [`jaxfric.plot`][jaxfric.plot] can use it too."""

from __future__ import annotations

__all__ = ["STYLES", "style"]

#: One look per model family (and per solver), shared by every figure: ``family ->
#: matplotlib line keywords``. [`style`][jaxfric.styles.style] picks the entry from a label. The
#: least-squares baseline (asymmetric Coulomb + viscous + offset by least squares) is a
#: dashed black line, so that it stays visible under and beside the models.
STYLES: dict[str, dict] = {
    "measured": dict(color="0.15"),
    "baseline": dict(color="black", ls="--"),
    "ENN full": dict(color="tab:cyan"),
    "ENN": dict(color="tab:blue"),
    "LuGre": dict(color="tab:red"),
    "Coulomb": dict(color="tab:green"),
    "Stribeck": dict(color="tab:purple"),
    "Dahl": dict(color="tab:olive"),
    "GMS": dict(color="tab:pink"),
    "Cylinder": dict(color="tab:brown"),
    "no compensation": dict(color="0.55"),
    "true friction": dict(color="goldenrod", ls=":"),
    "MAPSO-NMDS": dict(color="tab:blue"),
    "PSO": dict(color="tab:orange"),
    "CMA-ES": dict(color="tab:green"),
}

# label words -> family, checked in this order (the first match wins)
_STYLE_WORDS = (
    (("baseline", "least squares", "least-squares", "ls map", "idim"), "baseline"),
    (("measured",), "measured"),
    (("elman_full", "elman full", "enn full", "full elman"), "ENN full"),
    (("enn", "elman"), "ENN"),
    (("lugre",), "LuGre"),
    (("stribeck",), "Stribeck"),
    (("coulomb",), "Coulomb"),
    (("dahl",), "Dahl"),
    (("gms", "maxwell"), "GMS"),
    (("cylinder",), "Cylinder"),
    (("no compensation", "none"), "no compensation"),
    (("true friction", "ideal"), "true friction"),
    (("mapso-nmds", "mapso–nmds", "mapso_nmds", "mapso"), "MAPSO-NMDS"),
    (("cma",), "CMA-ES"),
    (("pso",), "PSO"),
)
_SPARE_COLOURS = ("tab:gray", "darkorange", "teal", "indigo", "crimson", "sienna")


def style(label: str, index: int = 0) -> dict:
    """Line keywords (``color``, and ``ls`` where the family has one) for a model or
    solver ``label``: its family's entry of [`STYLES`][jaxfric.styles.STYLES], found by the words of the
    label (``"ENN (30 neurons)"`` -> ENN, ``"LuGre (asymmetric + offset)"`` -> LuGre,
    ``"LS baseline"`` -> baseline), else a spare colour chosen by ``index``."""
    text = str(label).lower()
    for words, family in _STYLE_WORDS:
        if any(w in text for w in words):
            return dict(STYLES[family])
    return dict(color=_SPARE_COLOURS[index % len(_SPARE_COLOURS)])
