"""Road database update: what an extraction says about an existing road database.

:func:`conflate` matches extracted centre lines to a database's lines and returns the change
layers (``confirmed``, ``missing``, ``new``, ``moved``, ``proposed_update``);
:func:`read_database` reads a database from any OGR source with its feature ids;
:func:`edit_database`, :func:`score_changes` and :func:`pooled_scores` make and score a
benchmark with known changes (fakes kept clear of :func:`truth_pavement`).
"""
from .benchmark import (FUSA_UNLABELLED_PAVEMENT, EditedDatabase, edit_database,
                        pooled_scores, score_changes, truth_pavement)
from .conflate import CHANGES, LAYERS, MatchOptions, conflate
from .sources import read_database

__all__ = ["CHANGES", "FUSA_UNLABELLED_PAVEMENT", "LAYERS", "EditedDatabase", "MatchOptions",
           "conflate", "edit_database", "pooled_scores", "read_database", "score_changes",
           "truth_pavement"]
