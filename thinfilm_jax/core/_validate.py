"""Checks at the public boundary: bad input raises a clear error naming the argument.

What is checked where (README "Input checking"):

* **Concrete values** (NumPy arrays, Python numbers and lists, JAX arrays outside a trace):
  every public function checks ranges, finiteness, shapes, option names, sizes and orders
  before it runs and raises `ValueError` / `TypeError` naming the argument and its allowed
  range. Plain Python lists and tuples are accepted as arrays. Values within a few ulps
  outside a closed range ([0, 1] for cos θ, [0, π/2] for θ_o) are rounding, not errors:
    cos θ is clamped into [0, 1], θ_o is accepted as is (`ROUNDING_ULPS`).
* **Traced values** (inside `jax.jit`, `jax.vmap`, `jax.grad`): values are unknown while
  tracing, so by default nothing is checked (dtype checks still run: complex where a real
  is needed raises). Opt in with `thinfilm_jax.checked`: inside a function wrapped by
  ``checked(fn)`` (or traced inside a ``with checked():`` block) the same range checks
  become `equinox.error_if` checks that raise at run time, e.g.
  ``jax.jit(tf.checked(lambda f: tf.airy_reflectance(f, c, lam)))``. They cost a reduction
  and a branch per checked argument.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import numbers
from collections.abc import Iterable

import jax
import jax.numpy as jnp
import numpy as np

from .film import Film
from .stack import Stack

#: Values at most this many ulps (of the bound's magnitude, at least of 1) outside a closed
#: range are taken as rounding: cos θ = cos(π/2) in float32 is −4.4e-8 (0.4 ulp of 1).
ROUNDING_ULPS = 4

_CHECKED = contextvars.ContextVar("thinfilm_jax_checked", default=False)


class checked(contextlib.ContextDecorator):
    """Opt-in run-time checks of traced inputs (`equinox.error_if`).

    As a function wrapper, the recommended form, which works under `jax.jit` caching:

        >>> import jax, thinfilm_jax as tf
        >>> f = jax.jit(tf.checked(lambda film: tf.airy_reflectance(film, 0.6, 550.0)))
        >>> f(tf.Film(600.0, 1.3, 2.0, -0.5))  # doctest: +SKIP
        Traceback (most recent call last):
        ...
        jax.errors.JaxRuntimeError: ... film.kappa_base must lie in [0.0, inf] ...

    (the error is raised when the result is computed; its message names the argument).

    Wrap the function before jitting it: ``checked(jax.jit(f))`` would reuse an unchecked
    trace of ``jax.jit(f)``. As a context, ``with tf.checked(): ...`` checks what is *traced*
    inside the block: a jitted function traced (first called) outside the block stays
    unchecked when called inside it (JAX reuses the compiled trace). Concrete inputs are
    always checked.
    """

    def __enter__(self):
        self._token = _CHECKED.set(True)
        return self

    def __exit__(self, *exc):
        _CHECKED.reset(self._token)
        return False

    def __new__(cls, fn=None):
        self = super().__new__(cls)
        if fn is None:
            return self
        if not callable(fn):
            raise TypeError(f"checked() takes a function (or no argument), got "
                            f"{type(fn).__name__}")

        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            with cls():
                return fn(*args, **kwargs)

        return wrapper


def checking() -> bool:
    """True while traced inputs are checked (inside `checked`)."""
    return _CHECKED.get()


def is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _values(x):
    return np.asarray(x)


def _error_if(x, bad, msg):
    import equinox as eqx

    return eqx.error_if(x, bad, msg)


def as_array(name: str, x):
    """`x` unchanged if it is a number or an array; lists/tuples become arrays.

    Anything else (a string, None, a dict, a ragged list) raises a TypeError naming `name`.
    """
    if isinstance(x, (list, tuple)):
        if any(not is_concrete(v) for v in jax.tree.leaves(x)):  # traced entries (grad, jit):
            return jnp.asarray(x, jnp.result_type(*jax.tree.leaves(x), float))  # no checks
        try:
            a = np.asarray(x)
        except ValueError:
            raise TypeError(f"{name} must be a number or a rectangular array of numbers; got "
                            f"a ragged {type(x).__name__}") from None
        if a.dtype == object or not (np.issubdtype(a.dtype, np.number)
                                     or np.issubdtype(a.dtype, np.bool_)):
            raise TypeError(f"{name} must be a number or an array of numbers; got "
                            f"{type(x).__name__} {str(x)[:60]}")
        return jnp.asarray(a, jnp.result_type(float) if np.issubdtype(a.dtype, np.floating)
                           or np.issubdtype(a.dtype, np.integer) else None)
    if isinstance(x, (numbers.Number, np.ndarray, np.generic, jax.Array)) or not is_concrete(x):
        if isinstance(x, (np.ndarray, np.generic)) and not (np.issubdtype(x.dtype, np.number)
                                                              or x.dtype == np.bool_):
            raise TypeError(f"{name} must be numeric; got an array of dtype {x.dtype}")
        return x
    raise TypeError(f"{name} must be a number or an array of numbers; got "
                    f"{type(x).__name__} {str(x)[:60]!r}")


def check_real(name: str, x):
    if jnp.iscomplexobj(x):
        raise TypeError(f"{name} must be real; got complex values (only Film.eta_base may be "
                        f"complex, read as eta_base + 1j*kappa_base)")
    return x


def check_finite(name: str, x):
    """`x`, after checking it holds no NaN/inf (concrete; traced only inside `checked`)."""
    x = check_real(name, as_array(name, x))
    if is_concrete(x):
        v = _values(x)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be finite; got NaN or inf in {name}")
    elif checking():
        x = _error_if(x, ~jnp.all(jnp.isfinite(x)), f"{name} must be finite; got NaN or inf")
    return x


def _slack(x, bound, ulps):
    if not ulps or bound is None:
        return 0.0
    dt = x.dtype if hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jnp.floating) \
        else np.dtype(float)
    return ulps * float(np.finfo(dt).eps) * max(1.0, abs(float(bound)))


def check_range(name: str, x, lo=None, hi=None, *, lo_open=False, hi_open=False, why="",
                ulps: int = 0, clamp: bool = False):
    """`x`, after checking that every value lies in [lo, hi] (or open ends).

    Values at most `ulps` ulps outside a closed end are rounding: accepted, and clamped onto
    the end if `clamp`. Lists become arrays. Concrete values raise a ValueError naming `name`
    and the range; traced values are checked only inside `checked` (equinox.error_if).
    """
    x = check_real(name, as_array(name, x))
    lb = "(" if lo_open else "["
    hb = ")" if hi_open else "]"
    rng = f"{lb}{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}{hb}"
    if not is_concrete(x):
        if checking():
            lo_s, hi_s = _slack(x, lo, ulps), _slack(x, hi, ulps)
            ok = jnp.isfinite(x)
            if lo is not None:
                ok &= (x > lo) if lo_open else (x >= lo - lo_s)
            if hi is not None:
                ok &= (x < hi) if hi_open else (x <= hi + hi_s)
            x = _error_if(x, ~jnp.all(ok), f"{name} must lie in {rng}{why}")
        return x
    check_finite(name, x)
    v = _values(x)
    lo_s = 0.0 if lo_open else _slack(v, lo, ulps)
    hi_s = 0.0 if hi_open else _slack(v, hi, ulps)
    bad = np.zeros(v.shape, bool)
    if lo is not None:
        bad |= (v <= lo) if lo_open else (v < lo - lo_s)
    if hi is not None:
        bad |= (v >= hi) if hi_open else (v > hi + hi_s)
    if np.any(bad):
        first = v[bad].flat[0]
        raise ValueError(f"{name} must lie in {rng}{why}; got {first!r}")
    if clamp and ((lo is not None and np.any(v < lo)) or (hi is not None and np.any(v > hi))):
        x = jnp.clip(jnp.asarray(x), lo, hi)
    return x


def check_broadcast(names_values: Iterable[tuple[str, object]]) -> tuple[int, ...]:
    """The broadcast shape of the arguments, or a ValueError that names their shapes."""
    items = [(n, np.shape(v)) for n, v in names_values]
    try:
        return np.broadcast_shapes(*(s for _, s in items))
    except ValueError:
        desc = ", ".join(f"{n} {s}" for n, s in items)
        raise ValueError(f"arguments have incompatible shapes: {desc}") from None


def _is_model(x) -> bool:
    """An index model (SPEC §12): a callable pytree, not a number or an array."""
    return callable(x) and not isinstance(x, (np.ndarray, jax.Array))


def check_index(name: str, eta, wavelengths=None):
    """A constant index (real or complex n + iκ: finite, n > 0, κ ≥ 0) or an index model;
    a model must cover the concrete `wavelengths` (nm), else a ValueError names its range."""
    if _is_model(eta):
        if wavelengths is not None:
            lo, hi = getattr(eta, "wavelength_range", (0.0, np.inf))
            w = np.asarray(wavelengths, float)
            if w.size and (w.min() < lo or w.max() > hi):
                label = getattr(eta, "name", "") or type(eta).__name__
                raise ValueError(f"{name} ({label}) is defined on {lo:g}–{hi:g} nm; it is "
                                 f"needed on {w.min():g}–{w.max():g} nm (no extrapolation)")
        return eta
    eta = as_array(name, eta)
    if is_concrete(eta):
        v = np.asarray(eta)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be finite; got NaN or inf in {name}")
        if np.any(np.real(v) <= 0) or np.any(np.imag(v) < 0):
            raise ValueError(f"{name} must be n + iκ with n > 0 and κ >= 0; got {v!r}")
    return eta


def check_stack(stack, name: str = "stack", wavelengths=None) -> Stack:
    """Validate a `Stack` (SPEC §12): thicknesses finite and >= 0 with N = len(eta) on their
    last axis, every index `check_index` (models covering `wavelengths`)."""
    if not isinstance(stack, Stack):
        raise TypeError(f"{name} must be a thinfilm_jax.Stack, got {type(stack).__name__}")
    if not isinstance(stack.eta, (tuple, list)) or not stack.eta:
        raise ValueError(f"{name}.eta must be a non-empty sequence of N layer indices")
    d = check_range(f"{name}.thickness", as_array(f"{name}.thickness", stack.thickness), 0.0,
                    why=" (nm, d >= 0)")
    if np.shape(d)[-1:] != (len(stack.eta),):
        raise ValueError(f"{name}.thickness must hold the {len(stack.eta)} layer thicknesses on "
                         f"its last axis (one per eta); got shape {np.shape(d)}")
    named = [(f"{name}.eta[{i}]", e) for i, e in enumerate(stack.eta)]
    named += [(f"{name}.eta_base", stack.eta_base), (f"{name}.eta_outer", stack.eta_outer)]
    eta = check_indices(named, wavelengths)
    return Stack(d, tuple(eta[:-2]), eta[-2], eta[-1])


def check_indices(named, wavelengths=None) -> list:
    """`check_index` of every (name, index) pair; the failures, all of them, are one
    ValueError that lists each by its name (not only the first)."""
    out, problems = [], []
    for n, e in named:
        try:
            out.append(check_index(n, e, wavelengths))
        except ValueError as err:
            problems.append(str(err))
    if len(problems) == 1:
        raise ValueError(problems[0])
    if problems:
        raise ValueError(f"{len(problems)} indices are out of range: " + "; ".join(problems))
    return out


def check_material(x, name: str = "film", wavelengths=None):
    """A `Film` with constant indices (`check_film`) or what runs the stack code: a `Stack`,
    or a `Film` with index models (returned as its one-layer `Stack`, SPEC §12)."""
    if isinstance(x, Film) and any(_is_model(getattr(x, k))
                                   for k in ("eta_film", "eta_base", "eta_outer")):
        if _is_model(x.eta_base) and (not is_concrete(x.kappa_base)
                                      or np.any(np.asarray(x.kappa_base) != 0)):
            raise ValueError(f"{name}.kappa_base must be 0 when {name}.eta_base is an index "
                             f"model (the model carries κ)")
        for k in ("eta_film", "eta_base", "eta_outer"):
            v = getattr(x, k)
            if not _is_model(v) and np.ndim(v) != 0:
                raise ValueError(f"{name}.{k} must be a scalar when another index is a model "
                                 f"(only thickness varies per point; vmap over materials)")
        # the Film's own field names in the messages (not those of its one-layer Stack)
        check_indices([(f"{name}.{k}", getattr(x, k))
                       for k in ("eta_film", "eta_base", "eta_outer")], wavelengths)
        return check_stack(Stack.from_film(x._replace(
            eta_base=x.eta_base if _is_model(x.eta_base) else x.eta_base + 1j * x.kappa_base,
            kappa_base=0.0)), name, wavelengths)
    if isinstance(x, Stack):
        return check_stack(x, name, wavelengths)
    return check_film(x, name)


def check_film(film, name: str = "film") -> Film:
    """Validate a `Film` (SPEC §1 domain) and return it normalised: list fields as arrays
    and a complex `eta_base` η + iκ folded into (eta_base = η, kappa_base = kappa_base + κ)
    (`Film.real_base`). Callers must use the returned film."""
    if not isinstance(film, Film):
        raise TypeError(f"{name} must be a thinfilm_jax.Film, got {type(film).__name__}")
    if any(_is_model(getattr(film, k)) for k in ("eta_film", "eta_base", "eta_outer")):
        raise ValueError(f"{name} has a dispersive index (an index model): this path takes "
                         f"constant indices only (SPEC §12: the exact methods take it)")
    # Field by field by name (a list field is a pytree node, not a leaf: no tree.map here).
    film = film._replace(**{k: as_array(f"{name}.{k}", v)
                            for k, v in film._asdict().items()}).real_base()
    film = film._replace(
        thickness=check_range(f"{name}.thickness", film.thickness, 0.0, why=" (nm, d >= 0)"),
        eta_film=check_range(f"{name}.eta_film", film.eta_film, 1.0,
                             why=" (supported domain eta >= 1)"),
        eta_base=check_range(f"{name}.eta_base", film.eta_base, 0.0, lo_open=True),
        kappa_base=check_range(f"{name}.kappa_base", film.kappa_base, 0.0,
                               why=" (absorption kappa >= 0; a complex eta_base n + ik needs "
                                   "k >= 0)"),
        eta_outer=check_range(f"{name}.eta_outer", film.eta_outer, 1.0,
                              why=" (supported domain eta >= 1)"),
    )
    check_broadcast((f"{name}.{k}", v) for k, v in film._asdict().items())
    return film


def check_cos_theta(cos_theta, name: str = "cos_theta"):
    """cos θ in [0, 1]; rounding-level excursions (≤ `ROUNDING_ULPS` ulps) are clamped."""
    return check_range(name, cos_theta, 0.0, 1.0, ulps=ROUNDING_ULPS, clamp=True)


def check_angle(name: str, theta):
    """An angle in [0, π/2] radians; float32 π/2 (a rounding above π/2) is accepted."""
    return check_range(name, theta, 0.0, np.pi / 2, why=" (radians)", ulps=ROUNDING_ULPS)


def check_int(name: str, value, lo: int = 0) -> int:
    """A Python/NumPy integer (not bool) ≥ lo, returned as a plain int."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo:
        raise ValueError(f"{name} must be an int >= {lo}, got {value!r}")
    return int(value)


def check_choice(name: str, value, choices) -> None:
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"unknown {name} {value!r}; expected one of {sorted(choices)}")


def check_quadrature(value, name: str = "quadrature") -> tuple[int, int]:
    """A half-vector quadrature order pair (n_u ≥ 1, n_phi ≥ 2) as plain ints.

    The one spelling of a quadrature order across the library (`microfacet.patch_quadrature`,
    `patch_radiance`, `fit_film`, the Figure 7 driver)."""
    try:
        n_u, n_phi = value
        return check_int(f"{name}[0] (n_u)", n_u, 1), check_int(f"{name}[1] (n_phi)", n_phi, 2)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be a pair (n_u >= 1, n_phi >= 2) of ints, got "
                         f"{value!r}") from e


def check_directions(normal, view) -> None:
    """normal and view of an environment-map call: (..., 3), finite unit vectors (checked
    where concrete; a norm off 1 by more than 1e-3 is refused)."""
    for name, v in (("normal", normal), ("view", view)):
        if np.shape(v)[-1:] != (3,):
            raise ValueError(f"{name} must have shape (..., 3), got {np.shape(v)}")
        if is_concrete(v):
            check_finite(name, v)
            nrm = np.linalg.norm(np.asarray(v, float), axis=-1)
            if np.any(np.abs(nrm - 1) > 1e-3):
                raise ValueError(f"{name} must be unit vectors; got a norm of "
                                 f"{nrm.flat[np.argmax(np.abs(nrm - 1))]:.6g}")
