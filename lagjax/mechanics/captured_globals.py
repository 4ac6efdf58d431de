"""Numbers a user's L or H reads from module globals are frozen when it compiles.

`simulate` compiles a system's functions once and reuses the compiled program for
every later call with the same function (equinox compares the function, a static
part of the program, by identity). A module-level number the function reads —

    g = 9.81
    def L(q, qdot):
        return 0.5 * qdot**2 + g * jnp.cos(q)

— is read while tracing and becomes a constant of that program. Rebinding it later
(`g = 1.62`) changes nothing: the Earth answer comes back for the Moon, silently.
A system built after the rebinding is another program: `captured_identity` keeps
the captured numbers' values at construction as a static field of the system
(`Lagrangian.captured`, `Hamiltonian.captured`), so systems built before and after
compare unequal and `eqx.filter_jit` compiles anew. Reusing the same system object
still runs its first compilation, with the old value.

The sound way to vary a number is an argument, `L(q, qdot, t, args)` with
`simulate(..., args=...)`: arguments are traced, and a new value reuses the
compilation.

`warn_captured_numbers` reads, once when a `Lagrangian` or `Hamiltonian` is built,
which module globals the function loads (the `LOAD_GLOBAL` instructions of its code,
nested functions and the same module's helper functions included) and warns when
one of them is a number or an array (`CapturedNumberWarning`). Modules and
functions (`jnp`, `math`, a helper `V`) are not numbers and are never named; nor
are `UPPER_CASE` names, which by convention (PEP 8) are constants that do not
change, nor constants imported from `math` or NumPy (`pi`, `e`). Closures,
attributes of objects and functions defined in lagjax itself are not inspected.

References: the JAX documentation, "JIT mechanics: tracing and static variables"
(global values are baked in at trace time); PEP 8, "Constants".
"""

from __future__ import annotations

import dis
import functools
import hashlib
import inspect
import math
import sys
import types
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import numpy as np

# Helper functions followed from the user's function, at most this deep.
_HELPER_DEPTH = 3

# Frames in these folders are the library's; the warning points past them.
_LIBRARY_DIRECTORIES = (
    str(Path(__file__).resolve().parent.parent),  # lagjax
    str(Path(eqx.__file__).resolve().parent),
)


class CapturedNumberWarning(UserWarning):
    """A user's L or H reads a module-level number that compiling will freeze."""


def warn_captured_numbers(function: Callable | None, what: str) -> dict[str, Any]:
    """Warn (`CapturedNumberWarning`) when `function` reads module-level numbers;
    `what` names it in the message ("the Lagrangian L"). Returns them, {name: value}
    (empty for None), for `captured_identity`."""
    if function is None:
        return {}
    # Constants are part of the system's identity too (a rebound UPPER_CASE number
    # then recompiles a new system), but not warned about.
    found = captured_numbers(function, constants=True)
    warned = {k: v for k, v in found.items() if not _is_constant(k, v)}
    if not warned:
        return found
    shown = ", ".join(f"{name} = {_short(value)}" for name, value in warned.items())
    first = next(iter(warned))
    warnings.warn(
        f"{what} reads the module-level number(s) {shown}. Compiling freezes their "
        f"current values into the program of this system object, which is reused "
        f"on every later run of it: rebinding {first} afterwards silently gives the "
        f"results for the old value with this object (a system built after the "
        f"rebinding reads the new one). Pass numbers that may change through args — "
        f"define (q, qdot, t, args) or (q, p, t, args) and call "
        f"simulate(..., args=...) — or, for a true constant, name it in UPPER_CASE "
        f"(not warned about)",
        CapturedNumberWarning,
        stacklevel=_caller_stacklevel(),
    )
    return found


def captured_identity(*found: dict[str, Any]) -> tuple[tuple[str, str], ...]:
    """The captured numbers' values at construction as a hashable, comparable key:
    (name, fingerprint) pairs, the fingerprint a string (`_fingerprint`), so that
    NaN equals itself and a large array stays small.

    Held as a static field of the system, it makes two systems built before and
    after a rebinding unequal, and `eqx.filter_jit` compiles anew for the second.
    """
    pairs = {}
    for numbers in found:
        for name, value in numbers.items():
            pairs.setdefault(name, _fingerprint(value))
    return tuple(sorted(pairs.items()))


def _fingerprint(value: Any) -> str:
    """A number as its dtype and exact repr ("<f8 9.81"); an array as its dtype,
    shape and digest. Printed with the system, it also tells `lj.sweep`'s store
    (which fingerprints the system's printout) that the number changed."""
    array = np.asarray(value)
    if array.ndim == 0:
        return f"{array.dtype.str} {array.item()!r}"
    digest = hashlib.blake2b(np.ascontiguousarray(array).tobytes(), digest_size=16)
    return f"{array.dtype.str}{array.shape}:{digest.hexdigest()}"


def captured_numbers(function: Callable, constants: bool = False) -> dict[str, Any]:
    """{name: value} of the module-level numbers `function` reads (see the module
    docstring for what is and is not counted; `constants`: UPPER_CASE names and
    math/NumPy constants too)."""
    found: dict[str, Any] = {}
    visited: set[types.CodeType] = set()

    def visit(fn: Any, depth: int) -> None:
        code = getattr(fn, "__code__", None)
        namespace = getattr(fn, "__globals__", None)
        if not isinstance(code, types.CodeType) or not isinstance(namespace, dict):
            return
        if code in visited or str(namespace.get("__name__", "")).startswith("lagjax"):
            return
        visited.add(code)
        for name in _loaded_globals(code):
            if name not in namespace:  # a builtin, or not defined yet
                continue
            value = namespace[name]
            if _is_number(value) and (constants or not _is_constant(name, value)):
                found.setdefault(name, value)
            elif _is_helper(value, namespace) and depth < _HELPER_DEPTH:
                visit(value, depth + 1)

    visit(_plain_function(function), 0)
    return found


def _is_helper(value: Any, namespace: dict) -> bool:
    """A plain function of the same module as the user's (its own helper V(q))."""
    return isinstance(value, types.FunctionType) and value.__globals__ is namespace


def _plain_function(function: Any) -> Any:
    """The Python function behind a partial, a bound method or a `jax.jit`."""
    while True:
        if isinstance(function, functools.partial):
            function = function.func
        elif isinstance(function, types.MethodType):
            function = function.__func__
        elif hasattr(function, "__wrapped__"):
            function = inspect.unwrap(function)
            if hasattr(function, "__wrapped__"):  # unwrap stopped on a cycle
                return function
        else:
            return function


def _loaded_globals(code: types.CodeType) -> Iterator[str]:
    """Names the code loads as globals, nested code objects (lambdas, inner
    functions, comprehensions) included."""
    for instruction in dis.get_instructions(code):
        if instruction.opname in ("LOAD_GLOBAL", "LOAD_NAME"):
            yield str(instruction.argval)
    for constant in code.co_consts:
        if isinstance(constant, types.CodeType):
            yield from _loaded_globals(constant)


def _is_number(value: Any) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float, complex)):
        return True
    if isinstance(value, (np.ndarray, np.generic, jax.Array)):
        return np.issubdtype(np.asarray(value).dtype, np.number)
    return False


def _is_constant(name: str, value: Any) -> bool:
    """An UPPER_CASE name, or a constant imported from math or NumPy (pi, e)."""
    if name.isupper():
        return True
    return any(getattr(module, name, None) is value for module in (math, np))


def _short(value: Any) -> str:
    if isinstance(value, (int, float, complex)):
        return repr(value)
    array = np.asarray(value)
    if array.size == 1:
        return repr(array.item())
    return f"<array of shape {array.shape}>"


def _caller_stacklevel() -> int:
    """The `stacklevel` that points the warning at the first frame outside lagjax
    and equinox (the user's `Lagrangian(L)` line)."""
    frame = sys._getframe(1)  # the caller of this function: warn_captured_numbers
    level = 1
    while frame is not None and frame.f_code.co_filename.startswith(
        _LIBRARY_DIRECTORIES
    ):
        frame = frame.f_back
        level += 1
    return level
