"""Integer programs with PuLP, as both environments run them (the LiDAR minimum cover, the
imagery subgraph evaluation): one solver choice, one way to make variables."""
from __future__ import annotations

import pulp


def solver(*, time_limit_s: float | None = None, warm_start: bool = False):
    """A CBC solver PuLP can run: the system's ``COIN_CMD`` (Debian's ``coinor-cbc``, the
    only one in the QGIS environment, and the one PuLP 3 recommends), else PuLP's bundled
    ``PULP_CBC_CMD``.

    Raises
    ------
    RuntimeError
        When PuLP finds neither.
    """
    available = pulp.listSolvers(onlyAvailable=True)
    for name in ("COIN_CMD", "PULP_CBC_CMD"):
        if name in available:
            return pulp.getSolver(name, msg=False, timeLimit=time_limit_s,
                                  warmStart=warm_start)
    raise RuntimeError("no CBC solver for PuLP: install Debian's coinor-cbc "
                       f"(PuLP offers only {available})")


def variable(model: pulp.LpProblem, name: str, **kwargs) -> pulp.LpVariable:
    """A variable of ``model``; PuLP 3 deprecates free-standing variables, PuLP 2.6 (the QGIS
    environment's) has nothing else."""
    if hasattr(model, "add_variable"):
        return model.add_variable(name, **kwargs)
    return pulp.LpVariable(name, **kwargs)
