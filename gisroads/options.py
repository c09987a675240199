"""Options objects: the long parameter lists of the stages as frozen dataclasses.

A stage takes its options as one object whose fields carry the defaults (written once), and
keywords that change fields for one call (``**changes``), so ``extract_roads(path,
tile_m=200)`` and ``extract_roads(path, LidarOptions(tile_m=200))`` are the same call.
:func:`with_changes` sends each keyword to the object that has the field.
"""
from __future__ import annotations

import dataclasses


def with_changes(changes: dict, *options):
    """``options`` with ``changes`` applied, each keyword to the first object holding a
    field of that name.

    Parameters
    ----------
    changes : dict
        Field names and new values.
    *options : dataclass instances
        Frozen options objects (:func:`dataclasses.replace` makes the changed copies).

    Returns
    -------
    tuple
        The objects, changed, in the order given.

    Raises
    ------
    TypeError
        A keyword that none of the objects has as a field (as an unknown keyword argument
        does).

    Examples
    --------
    >>> from gisroads.options import with_changes
    >>> from gisroads.parallel import Parallel
    >>> from gisroads.lidar import LidarOptions
    >>> options, parallel = with_changes({"tile_m": 200.0, "workers": 2}, LidarOptions(),
    ...                                  Parallel())
    >>> options.tile_m, parallel.workers
    (200.0, 2)
    """
    remaining = dict(changes)
    changed = []
    for option in options:
        fields = {field.name for field in dataclasses.fields(option)}
        changed.append(dataclasses.replace(option, **{name: remaining.pop(name)
                                                      for name in list(remaining)
                                                      if name in fields}))
    if remaining:
        raise TypeError(f"unexpected keyword argument(s): {', '.join(sorted(remaining))}")
    return tuple(changed)
