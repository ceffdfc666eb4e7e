"""Numba kernels on arrays and scalars (docs/architecture.md §3); the modules above them wrap them."""

#: ``njit`` options of a helper kernel called only from other kernels, never from Python: numba
#: builds no CPython or C wrapper for it, which it would otherwise compile on a first run and never
#: call (about 50 ms of compile CPU a helper: docs/decisions.md, "First run: kernels compiled
#: by a worker process beside the command")
INNER = {"cache": True, "no_cpython_wrapper": True, "no_cfunc_wrapper": True}
