"""Shared MILP solver plumbing (tpvp.solvers): settings checks and both solvers on a tiny ILP."""

import pulp
import pytest

from tpvp.errors import ConfigError
from tpvp.path.config import TspConfig
from tpvp.setcover.config import SetCoverConfig
from tpvp.solvers import SOLVERS, check_solver_settings, milp_solver


def test_unknown_solver_is_one_config_error_line_naming_the_choices():
    with pytest.raises(ConfigError) as info:
        milp_solver("gurobi", 10.0, 1)
    message = str(info.value)
    assert "\n" not in message
    assert "gurobi" in message and all(repr(name) in message for name in SOLVERS)
    # The configs of both users report the same message.
    for config in (SetCoverConfig, TspConfig):
        with pytest.raises(ConfigError) as info:
            config(solver="gurobi")
        assert str(info.value) == message


@pytest.mark.parametrize(("time_limit", "threads", "field"),
                         [(0, 1, "time_limit"), (-1.0, 1, "time_limit"), ("10", 1, "time_limit"),
                          (10.0, 0, "threads"), (10.0, 1.5, "threads"), (10.0, True, "threads")])
def test_bad_limits_are_config_errors(time_limit, threads, field):
    with pytest.raises(ConfigError, match=field):
        check_solver_settings("cbc", time_limit, threads)
    with pytest.raises(ConfigError, match=field):
        milp_solver("highs", time_limit, threads)


def tiny_knapsack():
    """max 5a + 4b + 3c  s.t.  2a + 3b + c <= 5,  4a + b + 2c <= 11,  3a + 4b + 2c <= 8, binary."""
    prob = pulp.LpProblem("tiny", pulp.LpMaximize)
    a, b, c = (prob.add_variable(v, 0, 1, cat=pulp.LpBinary) for v in "abc")
    prob += 5 * a + 4 * b + 3 * c
    prob += 2 * a + 3 * b + c <= 5
    prob += 4 * a + b + 2 * c <= 11
    prob += 3 * a + 4 * b + 2 * c <= 8
    return prob, (a, b, c)


def test_both_solvers_reach_the_same_optimum():
    found = {}
    for name in SOLVERS:
        prob, variables = tiny_knapsack()
        prob.solve(milp_solver(name, 10.0, 1, gapRel=0.0))
        assert prob.sol_status == pulp.LpSolutionOptimal, name
        found[name] = (pulp.value(prob.objective), tuple(round(v.value()) for v in variables))
    # Brute force over the 8 assignments: a + b (value 9) is the only optimum.
    assert found == {name: (9.0, (1, 1, 0)) for name in SOLVERS}
