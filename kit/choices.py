"""The values the command line offers as ``choices``, as plain data.

The parser of every subcommand is built from these (``gyrocal CMD --help`` and an argument
error import nothing more than :mod:`argparse` needs); :mod:`gyrocal.kit.config` checks the
``gyrocal.toml`` keys against the same tuples.
"""

from __future__ import annotations

__all__ = ["METHODS", "PROTOCOLS"]

#: The estimators a user may choose, the default first: ``auto`` (the full model when the
#: recording's poses determine it and it is predicted better in general motion, else
#: paired-axis; :mod:`gyrocal.kit.pipeline`) and the names of
#: :data:`gyrocal.calib.estimators.METHODS` (kept here so the command line does not import scipy
#: to show its help).
METHODS = ("auto", "paired-axis", "iterative-ls", "levenberg-marquardt", "full-matrix")
#: The protocols, the default first: planned with poses for the full matrix (hardware_docs/method.md
#: §9), planned for the jig without poses (the paper's diagonal model), or the paper's.
PROTOCOLS = ("full", "auto", "paper")
