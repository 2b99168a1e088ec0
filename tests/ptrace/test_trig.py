"""ptrace.trig's inline sine and cosine against libm (and 2 pi u against a long-double reference):
the accuracy its docstring promises."""
import numpy as np
from numba import njit

from ptrace.trig import sincos, sincos_2pi


@njit(cache=True)
def _table(x):
    out = np.empty((x.shape[0], 4))
    for i in range(x.shape[0]):
        out[i, 0], out[i, 1] = sincos(x[i])
        out[i, 2], out[i, 3] = sincos_2pi(x[i])
    return out


def _ulps(values, reference):
    return np.max(np.abs(values - reference) / np.spacing(np.abs(reference)))


def test_sincos_is_within_one_ulp_of_libm():
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.uniform(-100.0, 100.0, 200_000), rng.uniform(0.0, 4 * np.pi, 200_000),
                        np.arange(-16, 17) * (np.pi / 4), [0.0, 1e-300, -1e-12]])
    out = _table(x)
    assert np.max(np.abs(out[:, 0] - np.cos(x))) <= 1.2e-16
    assert np.max(np.abs(out[:, 1] - np.sin(x))) <= 1.2e-16
    away = (np.abs(np.sin(x)) > 1e-3) & (np.abs(np.cos(x)) > 1e-3)
    assert _ulps(out[away, 0], np.cos(x[away])) <= 1.0
    assert _ulps(out[away, 1], np.sin(x[away])) <= 1.0


def test_sincos_2pi_is_closer_to_the_exact_angle_than_libm():
    u = np.random.default_rng(8).uniform(0.0, 1.0, 200_000)
    out = _table(u)
    turn = 2 * np.longdouble("3.14159265358979323846264338327950288")
    angle = turn * u.astype(np.longdouble)
    exact_cos, exact_sin = np.cos(angle), np.sin(angle)
    if np.finfo(np.longdouble).eps < 1e-18:     # an extended long double: a reference
        assert float(np.max(np.abs(out[:, 2] - exact_cos))) <= 2e-16
        assert float(np.max(np.abs(out[:, 3] - exact_sin))) <= 2e-16
    assert np.max(np.abs(out[:, 2] - np.cos(2 * np.pi * u))) <= 1e-15
    assert np.max(np.abs(out[:, 3] - np.sin(2 * np.pi * u))) <= 1e-15
    quarters = _table(np.array([0.0, 0.25, 0.5, 0.75]))
    assert np.array_equal(quarters[:, 2], [1.0, 0.0, -1.0, 0.0])
    assert np.array_equal(quarters[:, 3], [0.0, 1.0, 0.0, -1.0])
