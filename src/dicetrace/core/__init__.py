"""numba kernels: pure, allocation-free per step, status codes instead of exceptions.

This layer imports nothing of dicetrace above ``params`` (enforced by
import-linter, see pyproject.toml) and no I/O library.
"""
