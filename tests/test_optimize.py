"""The PuLP set-up both integer programs share, in both environments."""
import pulp

from gisroads.optimize import solver, variable


def test_solver_is_cbc_and_solves_a_small_program():
    assert type(solver()).__name__ in ("PULP_CBC_CMD", "COIN_CMD")
    model = pulp.LpProblem("knapsack", pulp.LpMaximize)
    x = [variable(model, f"x{i}", cat=pulp.LpBinary) for i in range(3)]
    model += 3 * x[0] + 2 * x[1] + 2 * x[2]
    model += 2 * x[0] + x[1] + x[2] <= 2
    model.solve(solver(time_limit_s=10))
    assert [v.value() for v in x] == [0, 1, 1]
