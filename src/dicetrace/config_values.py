"""The configuration layer's one error, and how it reads and shows values.

:class:`ConfigError` is what every check of a configuration raises
(:mod:`dicetrace.params`, the windows and resolutions of
:mod:`dicetrace.windows`): a ValueError that names the field at fault, so a
command line can say which option, and the explorer which query parameter,
was wrong.  The bottom of dicetrace: it imports numpy only.
"""

from __future__ import annotations

import numpy as np


def is_number(v) -> bool:
    """A real number that is not a bool (``dt_s=True`` is no step); numpy reals count.

    An integer beyond float64's range (``t_max_s=10**400``) is no number either:
    the checks that follow (``math.isfinite``) would raise OverflowError on it.
    """
    if not isinstance(v, (int, float, np.integer, np.floating)) or isinstance(v, (bool, np.bool_)):
        return False
    try:
        float(v)
    except OverflowError:
        return False
    return True


def plain(v):
    """A numpy scalar (or a number read from text) as the Python number it holds (stored and written as one)."""
    if isinstance(v, np.generic):
        return v.item()
    return float(v) if isinstance(v, _FromText) else v


def show(v) -> str:
    """A value for a message: 100.0, not np.float64(100.0); a tuple of them; a number read from text as that text."""
    if isinstance(v, tuple):
        return "(" + ", ".join(show(x) for x in v) + ("," if len(v) == 1 else "") + ")"
    return repr(plain(v) if not isinstance(v, _FromText) else v)


class ConfigError(ValueError):
    """A configuration value is malformed or out of range: the one error of the configuration layer.

    ``fields`` names what is at fault (a :class:`Preset` or :class:`Numerics`
    field, ``preset``, ``v_impact_cm_s``, or ``window``, ``z``, ``res`` of an
    IC space); ``field`` is the first.  The command line turns it into
    "--option: message", the explorer into a 400 naming its parameter.
    """

    def __init__(self, fields: str | tuple[str, ...], message: str):
        super().__init__(message)
        self.fields = (fields,) if isinstance(fields, str) else tuple(fields)
        self.field = self.fields[0]
        self.message = message

    def __reduce__(self):  # pickled whole (a Dask worker's error reaches the client naming its field)
        return type(self), (self.fields, self.message)


class _FromText(float):
    """A number read from option text by :func:`read_number`; messages show the text as it was given."""

    def __repr__(self) -> str:
        return repr(self.text)


def read_number(field: str, what: str, value):
    """``value``, or the number its text spells (the one reader of option text for ``make_config``)."""
    if not isinstance(value, str):
        return value
    try:
        v = _FromText(value.strip())
    except ValueError:
        raise ConfigError(field, f"{what}, got {value!r}") from None
    v.text = value
    return v
