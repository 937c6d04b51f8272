"""Solvers of :class:`RoutingProblem`: OR-Tools (the paper's formulation) and PyVRP.

Both return, for each robot, the candidate indices it visits in order. A backend may return
fewer points than the optimum; it never returns an infeasible plan (checked by the caller).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from marl_cover.agents.experts.problem import UNREACHABLE, RoutingProblem

BACKENDS = ("pyvrp", "ortools")


def solve(
    problem: RoutingProblem,
    backend: str,
    time_limit: float,
    seed: int = 0,
    max_iterations: int | None = None,
    initial: list[list[int]] | None = None,
) -> list[list[int]]:
    """Routes (candidate indices per robot) from the named backend.

    ``initial`` (feasible candidate-index routes, such as the previous step's plan) warm-starts
    the search.

    With ``max_iterations`` the search stops after that many iterations (PyVRP) or solutions
    (OR-Tools) instead of after ``time_limit``, which makes it deterministic for a seed.

    Raises:
        ValueError: an unknown backend name.
    """
    if problem.num_candidates == 0:
        return [[] for _ in range(problem.num_robots)]
    if backend == "pyvrp":
        return solve_pyvrp(problem, time_limit, seed, max_iterations, initial)
    if backend == "ortools":
        return solve_ortools(problem, time_limit, max_iterations, initial)
    raise ValueError(f"unknown routing backend {backend!r}; choose one of {BACKENDS}")


def solve_ortools(
    problem: RoutingProblem,
    time_limit: float,
    max_solutions: int | None = None,
    initial: list[list[int]] | None = None,
) -> list[list[int]]:
    """The paper's formulation, with per-robot start nodes instead of a dummy depot.

    Open routes end at a dummy location reached at no cost; a hop budget is a "Time"
    dimension with slack 0; each candidate is an optional node (a disjunction whose penalty is
    its prize); guided local search within ``time_limit`` seconds; the transit matrix is
    registered as a matrix, not a Python callback.
    """
    from ortools.constraint_solver import pywrapcp, routing_enums_pb2

    r, c = problem.num_robots, problem.num_candidates
    end = r + c
    matrix = np.zeros((r + c + 1, r + c + 1), dtype=np.int64)
    matrix[: r + c, : r + c] = np.minimum(problem.distance, UNREACHABLE)
    matrix[:, end] = 0
    matrix[end, :] = UNREACHABLE
    manager = pywrapcp.RoutingIndexManager(r + c + 1, r, list(range(r)), [end] * r)
    routing = pywrapcp.RoutingModel(manager)
    transit = routing.RegisterTransitMatrix(matrix.tolist())
    routing.SetArcCostEvaluatorOfAllVehicles(transit)
    routing.AddDimensionWithVehicleCapacity(
        transit, 0, [int(b) for b in problem.budget], True, "hops"
    )
    for k, prize in enumerate(problem.prizes().tolist()):
        routing.AddDisjunction([manager.NodeToIndex(r + k)], prize)
    params = pywrapcp.DefaultRoutingSearchParameters()
    params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    params.local_search_metaheuristic = (
        routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    )
    if max_solutions is None:
        params.time_limit.FromMilliseconds(max(1, int(1000 * time_limit)))
    else:
        params.solution_limit = max_solutions
    start = None
    if initial is not None and any(initial):
        routing.CloseModelWithParameters(params)
        start = routing.ReadAssignmentFromRoutes(
            [[r + k for k in route] for route in initial], True
        )
    solution = (
        routing.SolveFromAssignmentWithParameters(start, params)
        if start is not None
        else routing.SolveWithParameters(params)
    )
    routes: list[list[int]] = [[] for _ in range(r)]
    if solution is None:
        return routes
    for vehicle in range(r):
        index = solution.Value(routing.NextVar(routing.Start(vehicle)))
        while not routing.IsEnd(index):
            routes[vehicle].append(manager.IndexToNode(index) - r)
            index = solution.Value(routing.NextVar(index))
    return routes


def solve_pyvrp(
    problem: RoutingProblem,
    time_limit: float,
    seed: int = 0,
    max_iterations: int | None = None,
    initial: list[list[int]] | None = None,
) -> list[list[int]]:
    """Prize-collecting VRP in PyVRP: one start depot per robot, a shared free end depot,
    optional clients with prizes, a maximum route distance per robot."""
    import pyvrp
    from pyvrp.stop import MaxIterations, MaxRuntime

    r, c = problem.num_robots, problem.num_candidates
    # locations: robot starts 0..r-1, end depot r, clients r+1..r+c
    n = r + 1 + c
    matrix = np.full((n, n), UNREACHABLE, dtype=np.int64)
    order = np.r_[np.arange(r), np.arange(r, r + c)]  # problem index of each non-end location
    position = np.r_[np.arange(r), np.arange(r + 1, n)]
    matrix[np.ix_(position, position)] = np.minimum(
        problem.distance[np.ix_(order, order)], UNREACHABLE
    )
    matrix[:, r] = 0
    np.fill_diagonal(matrix, 0)
    locations = [pyvrp.Location(0.0, 0.0) for _ in range(n)]
    depots = [pyvrp.Depot(i) for i in range(r + 1)]
    prizes = problem.prizes().tolist()
    clients = [pyvrp.Client(r + 1 + k, prize=prizes[k], required=False) for k in range(c)]
    vehicles = [
        pyvrp.VehicleType(1, start_depot=i, end_depot=r, max_distance=int(problem.budget[i]))
        for i in range(r)
    ]
    matrices: list[Any] = [matrix, np.zeros_like(matrix)]  # pyvrp's stubs: ndarray[int, ...]
    data = pyvrp.ProblemData(locations, clients, depots, vehicles, matrices[:1], matrices[1:])
    stop = MaxRuntime(time_limit) if max_iterations is None else MaxIterations(max_iterations)
    start = None
    if initial is not None and any(initial):
        start = pyvrp.Solution(
            data, [pyvrp.Route(data, route, v) for v, route in enumerate(initial) if route]
        )
    result = pyvrp.solve(data, stop, seed=seed, collect_stats=False, initial_solution=start)
    routes: list[list[int]] = [[] for _ in range(r)]
    if not result.best.is_feasible():
        return routes
    for route in result.best.routes():
        vehicle = route.vehicle_type()
        routes[vehicle] = [a.idx for a in route if a.type == pyvrp.ActivityType.CLIENT]
    return routes
