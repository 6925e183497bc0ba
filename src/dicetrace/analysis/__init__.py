"""Analysis of scan results: basins, cells, boundaries, Wada tests, settle times, vertices, Lyapunov and escape rates.

Pure functions over rolls tables (one row per initial condition) and label
grids (integer arrays indexed ``[i, j(, k)]``; labels 1..6 faces, 0 undefined,
-1 did not settle). Measures that need new simulations take a
``classify(points) -> labels`` callable instead of importing the simulator.
Plotting lives in :mod:`dicetrace.analysis.plot` (matplotlib imported lazily)
and is not re-exported here.

Vocabulary follows Attractors.jl (``group_features``, ``basins_fractions``,
``basin_entropy``, ``uncertainty_exponent``, ``basins_fractal_test``).
"""

from types import ModuleType as _ModuleType

from .boundaries import (
    BasinEntropy, BoxCountingDimension, PowerLawFit, basin_entropy, boundary_box_fraction, boundary_dimension,
    boundary_fraction, boundary_mask, box_counting_dimension, fit_power_law,
)
from .agreement import Agreement, agreement
from .cells import cells_table, label_cells, same_cell, slice_cell_components
from .escape import EscapeRate, escape_rate, survival_function
from .fractality import FractalTestResult, basins_fractal_test, smooth_boundary_sbb
from .grouping import (
    UNDEFINED_LABEL, UNSETTLED_LABEL, AbstractGroupingConfig, GroupByContactSequence, GroupByOutcome,
    basins_fractions, basins_fractions_table, canonical_contact_sequence, contact_sequence_text,
    cube_node_permutations, group_features, parse_contact_sequence, permute_contact_sets, wilson_interval,
)
from .lyapunov import FiniteTimeLyapunov, LyapunovEstimate, finite_time_lyapunov, lyapunov_benettin
from .repetition import find_periods, label_autocorrelation, periodic_cells_connected
from .settle import (
    BoundaryBracket, SettleFit, bisect_boundary, edge_balance_rate, fit_settle_divergence, settle_profile,
)
from .sweep import chaos_measures, chaos_sweep
from .uncertainty import (
    UncertaintyExponent, uncertainty_exponent, uncertainty_exponent_perturbation, uncertainty_exponent_resolution,
)
from .vertices import find_vertices
from .wada import WadaGridResult, WadaMergeResult, wada_grid_test, wada_merge_test
from .wedge import (
    ball_hill_energy, ball_hill_outcome, ball_hill_outcome_energy, ball_hill_saddle_rate,
    ball_hill_separatrices, ball_hill_transit_time, ball_hill_vector_field,
)

#: Every name imported above: the public names of the submodules that this package re-exports.
__all__ = [_n for _n, _v in list(globals().items()) if not _n.startswith("_") and not isinstance(_v, _ModuleType)]
