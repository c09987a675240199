"""Options objects: the long parameter lists of the stages as frozen dataclasses.

A stage takes its options as one object whose fields carry the defaults (written once), and
keywords that change fields for one call (``**changes``), so ``extract_roads(path,
tile_m=200)`` and ``extract_roads(path, LidarOptions(tile_m=200))`` are the same call.
:func:`with_changes` sends each keyword to the object that has the field;
:func:`keyword_defaults` reads the defaults of a function's keywords, its options objects'
fields among them.
"""
from __future__ import annotations

import dataclasses
import inspect


def keyword_defaults(function) -> dict:
    """``{keyword: default}`` of everything ``function`` takes by keyword: its parameters
    (``inspect.Parameter.empty`` where there is no default) and, in place of a parameter
    whose default is an options object (a dataclass instance, its fields changed through
    ``**changes``), that object's fields.

    A field's default is that of the first options object holding it, where
    :func:`with_changes` sends the keyword; a parameter of the same name takes the keyword
    itself, so its default wins over the field's.

    Parameters
    ----------
    function : callable

    Returns
    -------
    dict
        In the order of the signature, an options object's fields in its place.

    Examples
    --------
    >>> from gisroads.lidar.hypotheses import T_BD, road_hypotheses
    >>> from gisroads.options import keyword_defaults
    >>> keyword_defaults(road_hypotheses)["t_bd"] == T_BD
    True
    """
    parameters = [parameter for parameter in inspect.signature(function).parameters.values()
                  if parameter.kind is not inspect.Parameter.VAR_KEYWORD]
    plain = {parameter.name for parameter in parameters
             if not dataclasses.is_dataclass(parameter.default)}
    defaults = {}
    for parameter in parameters:
        if dataclasses.is_dataclass(parameter.default):
            for field in dataclasses.fields(parameter.default):
                if field.name not in plain:
                    defaults.setdefault(field.name, getattr(parameter.default, field.name))
        else:
            defaults[parameter.name] = parameter.default
    return defaults


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
