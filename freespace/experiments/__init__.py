"""The paper's experiments: every network trained with and without the augmentation, tables, figures.

:func:`freespace.experiments.reproduce.reproduce` runs a campaign (its module keeps the name: the function is
not re-exported here, where it would hide the module); :mod:`~freespace.experiments.variants` names the
variants and gains, :mod:`~freespace.experiments.protocol` reads a study's :class:`Protocol`;
:mod:`~freespace.experiments.cells` runs one cell; :mod:`~freespace.experiments.tables` collects the run folders into
the tables
(:func:`write_tables`); :mod:`~freespace.experiments.figures` draws them.
"""

from freespace.experiments.cells import evaluate_test_set, run_cell
from freespace.experiments.protocol import DataSource, Primary, Protocol
from freespace.experiments.tables import OUT_ENTRIES, write_tables
from freespace.experiments.variants import (
    DEFAULT_VARIANTS,
    GAINS,
    MAX_SEEDS,
    METRICS,
    PAPER_NETWORKS,
    VARIANTS,
    TestRoots,
    Variant,
    parse_cell,
    parse_models,
    parse_test_roots,
    parse_variants,
)

__all__ = ["run_cell", "write_tables", "evaluate_test_set", "parse_models", "parse_variants",
           "parse_cell", "parse_test_roots", "Variant", "VARIANTS", "DEFAULT_VARIANTS", "GAINS", "METRICS",
           "MAX_SEEDS", "PAPER_NETWORKS", "OUT_ENTRIES", "Primary", "Protocol", "DataSource", "TestRoots"]
