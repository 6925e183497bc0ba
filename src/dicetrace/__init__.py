"""dicetrace: the chaos of a rolling die, simulated, recorded and analysed."""

__version__ = "0.1.0"
