"""Test functions against independent references: scipy, NumPy formulas, hand values."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

from jaxfric import functions as F


def np_griewank(x):
    i = np.arange(1, x.size + 1)
    return 1 + np.sum(x**2) / 4000 - np.prod(np.cos(x / np.sqrt(i)))


def np_ackley(x):
    d = x.size
    return (
        -20 * np.exp(-0.2 * np.sqrt(np.sum(x**2) / d))
        - np.exp(np.sum(np.cos(2 * np.pi * x)) / d)
        + 20
        + np.e
    )


def np_schwefel_1_2(x):
    return sum(sum(x[: i + 1]) ** 2 for i in range(x.size))


REFERENCES = {
    "griewank": np_griewank,
    "ackley": np_ackley,
    "sphere": lambda x: np.sum(x**2),
    "schwefel": lambda x: np.sum(np.abs(x)) + np.prod(np.abs(x)),
    "schwefel_1_2": np_schwefel_1_2,
    "schwefel_2_21": lambda x: np.max(np.abs(x)),
    "rosenbrock": scipy.optimize.rosen,
    "rastrigin": lambda x: 10 * x.size + np.sum(x**2 - 10 * np.cos(2 * np.pi * x)),
}


#: Each test function compiled as one program per shape and dtype (called eagerly, each
#: of its jnp operations compiled as a program of its own); shared by the tests below.
JITTED = {name: jax.jit(t) for name, t in F.REGISTRY.items()}


@pytest.mark.parametrize("name", sorted(REFERENCES))
@pytest.mark.parametrize("dim", [1, 2, 7, 30])
def test_matches_independent_reference(name, dim):
    if name == "rosenbrock" and dim == 1:
        pytest.skip("Rosenbrock needs two coordinates")
    rng = np.random.default_rng(dim)
    hw = F.get(name).half_width
    with jax.enable_x64(True):
        for _ in range(5):
            x = rng.uniform(-hw, hw, dim)
            got = float(JITTED[name](jnp.asarray(x)))
            np.testing.assert_allclose(got, REFERENCES[name](x), rtol=1e-12, atol=1e-12)


def test_hand_computed_points():
    """Through the registry's jitted functions (the programs of the tests above where
    the dimension is theirs)."""
    with jax.enable_x64(True):
        a = jnp.asarray
        assert F.sphere is F.get("sphere").fn and F.schwefel is F.get("schwefel").fn
        assert float(JITTED["sphere"](a([1.0, 2.0]))) == 5.0
        assert float(JITTED["schwefel"](a([1.0, -2.0, 3.0]))) == 12.0  # 6 + 6
        assert float(JITTED["schwefel_1_2"](a([1.0, 2.0, 3.0]))) == 46.0  # 1 + 9 + 36
        assert float(JITTED["schwefel_2_21"](a([1.0, -5.0, 3.0]))) == 5.0
        assert float(JITTED["rosenbrock"](a([0.0, 0.0]))) == 1.0
        assert float(JITTED["rosenbrock"](a([2.0, 4.0]))) == 1.0  # 100·0 + (1−2)²
        np.testing.assert_allclose(float(JITTED["rastrigin"](a([0.5]))), 0.25 + 10 + 10, rtol=1e-14)
        # Griewank at x = (π, 0): 1 + π²/4000 − cos(π)·cos(0) = 2 + π²/4000
        np.testing.assert_allclose(
            float(JITTED["griewank"](a([np.pi, 0.0]))), 2 + np.pi**2 / 4000, rtol=1e-14
        )


@pytest.mark.parametrize("name", sorted(F.REGISTRY))
def test_known_optimum(name):
    """In the dimensions of the reference test above, whose programs it reuses."""
    t = F.get(name)
    with jax.enable_x64(True):
        for dim in (2, 7, 30):
            x_star = t.minimiser(dim)
            assert abs(float(JITTED[name](jnp.asarray(x_star))) - t.f_min) < 1e-12
            assert float(JITTED[name](jnp.asarray(x_star + 0.01))) > t.f_min


@pytest.mark.parametrize("name", sorted(F.REGISTRY))
def test_jit_vmap_grad_and_dtype(name):
    t = F.get(name)
    x = np.linspace(-1.3, 2.1, 12, dtype=np.float32)
    f = JITTED[name](x)
    assert f.shape == () and f.dtype == jnp.float32
    batch = np.stack([x, 0.5 * x, -x])
    np.testing.assert_allclose(
        jax.jit(jax.vmap(t.fn))(batch), [JITTED[name](b) for b in batch], rtol=1e-6
    )
    grad = jax.jit(jax.grad(t.fn))
    g = grad(x)
    assert g.shape == x.shape and bool(jnp.all(jnp.isfinite(g)))
    # grad is finite at the optimum too (Ackley's sqrt is guarded)
    assert bool(jnp.all(jnp.isfinite(grad(t.minimiser(12, np.float32)))))
    with jax.enable_x64(True):
        assert JITTED[name](x.astype(np.float64)).dtype == jnp.float64


def test_registry_and_objective_form():
    assert set(F.PAPER_TABLE1) <= set(F.REGISTRY)
    assert F.get("schwefel").fn is F.schwefel_2_22
    lo, hi = F.get("griewank").bounds(4)
    assert lo.tolist() == [-600.0] * 4 and hi.tolist() == [600.0] * 4
    assert F.objective("sphere") is F.objective("sphere")  # stable for jit caches
    assert float(F.objective("sphere")(jnp.ones(3), None)) == 3.0
    with pytest.raises(ValueError, match="unknown test function 'nope'"):
        F.get("nope")
