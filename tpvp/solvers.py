"""MILP solver plumbing shared by set cover (:mod:`tpvp.setcover`) and the exact path ILP (:mod:`tpvp.path`).

Two solvers are supported: CBC (the binary bundled with PuLP, driven through PuLP) and HiGHS (the
``highspy`` package, through PuLP or directly). This module checks the user-facing settings (solver
name, time limit, threads) once, with the same :class:`~tpvp.errors.ConfigError` messages
everywhere, and builds the solver objects.
"""

from __future__ import annotations

import os

import numpy as np

from tpvp.errors import ConfigError

SOLVERS = ("cbc", "highs")


def check_solver(name) -> str:
    """``name`` if it is one of :data:`SOLVERS`, else a one-line :class:`ConfigError`."""
    if not isinstance(name, str) or name not in SOLVERS:
        raise ConfigError(f"solver must be one of {SOLVERS}, got {name!r}")
    return name


def check_time_limit(value) -> float:
    """A positive number of seconds, as a float."""
    if isinstance(value, (bool, np.bool_)) or not (isinstance(value, (int, float, np.integer, np.floating))
                                                   and value > 0):
        raise ConfigError(f"time_limit must be a positive number of seconds, got {value!r}")
    return float(value)


def check_threads(value) -> int:
    """An integer >= 1."""
    if isinstance(value, (bool, np.bool_)) or not (isinstance(value, (int, np.integer)) and value >= 1):
        raise ConfigError(f"threads must be an integer >= 1, got {value!r}")
    return int(value)


def check_solver_settings(solver, time_limit, threads) -> None:
    """Check a config's ``solver``, ``time_limit`` and ``threads`` fields (in that order)."""
    check_solver(solver)
    check_time_limit(time_limit)
    check_threads(threads)


def cbc_command(**options):
    """PuLP's CBC command-line interface, preferring the binary bundled with PuLP.

    ``COIN_CMD`` pointed at the bundled binary is what ``PULP_CBC_CMD`` does, without its PuLP 4
    deprecation warning; a ``cbc`` on the PATH (``pip install pulp[cbc]``) is the fallback.
    ``options`` go to ``pulp.COIN_CMD`` (``msg``, ``timeLimit``, ``threads``, ``gapRel``, ``gapAbs``,
    ``logPath``, ...).
    """
    import pulp
    from pulp.apis import coin_api

    bundled = getattr(coin_api.PULP_CBC_CMD, "pulp_cbc_path", None)
    path = bundled if bundled and os.path.isfile(bundled) and os.access(bundled, os.X_OK) else None
    solver = pulp.COIN_CMD(path=path, **options)
    if not solver.available():
        raise ConfigError("solver 'cbc' is not available: PuLP's bundled CBC is missing and no 'cbc' is on "
                          "the PATH (pip install 'pulp[cbc]'), or use solver='highs'")
    return solver


def milp_solver(name: str, time_limit: float, threads: int = 1, msg: bool = False, **options):
    """A PuLP solver object for ``name`` ("cbc" or "highs") stopping after ``time_limit`` seconds.

    ``options`` (e.g. ``gapRel``, ``gapAbs``; ``logPath`` for CBC) are passed on unchanged. Raises
    :class:`ConfigError` for an unknown name, bad limits, or a solver that is not installed.
    """
    import pulp

    name = check_solver(name)
    time_limit = check_time_limit(time_limit)
    threads = check_threads(threads)
    if name == "cbc":
        return cbc_command(msg=msg, timeLimit=time_limit, threads=threads, **options)
    highspy_module()  # a clear error when HiGHS is missing (PuLP would fail only at solve time)
    return pulp.HiGHS(msg=msg, timeLimit=time_limit, threads=threads, **options)


def highspy_module():
    """The ``highspy`` module, or a :class:`ConfigError` saying how to install it."""
    try:
        import highspy
    except ImportError as exc:  # pragma: no cover - highspy ships with the project's environment
        raise ConfigError("solver 'highs' needs the highspy package (pip install highspy), "
                          "or use solver='cbc'") from exc
    return highspy


def parse_cbc_log(text: str) -> dict:
    """``result`` (CBC's "Result - ..." words), ``objective``, and ``lower_bound`` /
    ``upper_bound`` from the "Lower bound:" / "Upper bound:" lines of a CBC log, where present."""
    import re

    out = {}
    m = re.search(r"^Result - (.+)$", text, re.MULTILINE)
    if m:
        out["result"] = m.group(1).strip()
    for key, label in (("objective", "Objective value"), ("lower_bound", "Lower bound"), ("upper_bound", "Upper bound")):
        m = re.search(rf"^{label}:\s*([-+0-9.eE]+)", text, re.MULTILINE)
        if m:
            out[key] = float(m.group(1))
    return out


def solve_with_cbc_log(problem, time_limit: float, threads: int = 1, **options) -> dict:
    """Solve a PuLP ``problem`` with CBC and return :func:`parse_cbc_log` of its log (the log is
    the only place CBC states its proven bound)."""
    import tempfile

    fd, log_path = tempfile.mkstemp(prefix="tpvp_cbc_", suffix=".log")
    os.close(fd)
    try:
        problem.solve(milp_solver("cbc", time_limit, threads, logPath=log_path, **options))
        with open(log_path, errors="replace") as fh:
            return parse_cbc_log(fh.read())
    finally:
        os.remove(log_path)


def solve_pulp_milp(problem, variables, solver: str, time_limit: float, threads: int = 1, gap_abs: float = 0.0):
    """Solve a PuLP ``problem`` with CBC or HiGHS to a proven optimum (relative gap 0, absolute gap
    ``gap_abs``) or the time limit. Returns ``(chosen, optimal, bound, status)``: the indices of the
    binary ``variables`` set to 1 (None without an incumbent), whether optimality is proven, the
    solver's proven bound in the problem's own sense (an upper bound when maximising; None when
    not stated) and the solver's status words."""
    import pulp

    maximise = problem.sense == pulp.LpMaximize
    if solver == "cbc":
        log = solve_with_cbc_log(problem, time_limit, threads, gapRel=0.0, gapAbs=gap_abs)
        status = log.get("result", pulp.LpStatus[problem.status])
        optimal = problem.sol_status == pulp.LpSolutionOptimal and status.startswith("Optimal")
        if maximise:
            # With -max CBC prints "Upper bound" in the maximised sense; a "Lower bound" line would
            # be that of the negated (minimised) objective.
            bound = log.get("upper_bound", -log["lower_bound"] if "lower_bound" in log else None)
        else:
            bound = log.get("lower_bound")
    else:
        highspy = highspy_module()
        problem.solve(milp_solver("highs", time_limit, threads, gapRel=0.0, gapAbs=gap_abs, random_seed=0))
        highs = problem.solverModel
        model_status = highs.getModelStatus()
        status = highs.modelStatusToString(model_status)
        optimal = model_status == highspy.HighsModelStatus.kOptimal
        dual = float(highs.getInfo().mip_dual_bound)
        # PuLP hands HiGHS the negated objective of a maximisation.
        bound = (-dual if maximise else dual) if np.isfinite(dual) else None
    has_solution = problem.sol_status in (pulp.LpSolutionOptimal, pulp.LpSolutionIntegerFeasible)
    values = np.array([v.value() if v.value() is not None else 0.0 for v in variables])
    return (np.flatnonzero(values > 0.5) if has_solution else None), bool(optimal), bound, str(status)
