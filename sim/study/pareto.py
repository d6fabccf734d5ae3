"""The Pareto front of measured (cost, error) points, and the cheapest setting for a target error,
both judged beyond the measurement noise.

A point may carry the interval of each value (``cost_lo``/``cost_hi``, ``error_lo``/``error_hi``,
from :mod:`sim.study.stats`); without them the value itself is both ends.  One setting beats
another only where it is better *beyond* the noise (its interval entirely below the other's) on one
axis and not worse beyond the noise on the other; a setting meets a target error only if the upper
end of its error interval does; and settings whose costs cannot be told apart from the cheapest
such setting are named beside it (:func:`cost_ties`), never ranked below it.
"""

from __future__ import annotations

import math


def _num(v) -> bool:
    return v is not None and isinstance(v, (int, float)) and math.isfinite(v)


def _lo(p: dict, key: str) -> float:
    v = p.get(f"{key}_lo")
    return p[key] if v is None else v


def _hi(p: dict, key: str) -> float:
    v = p.get(f"{key}_hi")
    return p[key] if v is None else v


def clearly_below(q: dict, p: dict, key: str) -> bool:
    """``q``'s value of ``key`` is below ``p``'s beyond the noise (their intervals do not overlap)."""
    return _hi(q, key) < _lo(p, key)


def dominates(q: dict, p: dict) -> bool:
    """``q`` beats ``p`` beyond the noise on cost or error, and is not worse beyond it on the other."""
    return ((clearly_below(q, p, "cost") and not clearly_below(p, q, "error"))
            or (clearly_below(q, p, "error") and not clearly_below(p, q, "cost")))


def pareto_front(points: list[dict]) -> list[dict]:
    """The points no other point beats (:func:`dominates`), by cost.

    Without intervals this is the usual front: dominated when another has ``cost <=`` and
    ``error <=`` with at least one strict.  Points without a finite cost and error are left out.
    """
    pts = [p for p in points if _num(p["cost"]) and _num(p["error"])]
    front = [p for p in pts if not any(dominates(q, p) for q in pts if q is not p)]
    return sorted(front, key=lambda p: (p["cost"], p["error"]))


def cheapest_for(points: list[dict], target_error: float) -> dict | None:
    """The lowest-cost point whose error interval lies at or below ``target_error`` (ties: the lower
    error); None if no point meets the target beyond the noise."""
    ok = [p for p in points if _num(p["cost"]) and _num(p["error"]) and _hi(p, "error") <= target_error]
    return min(ok, key=lambda p: (p["cost"], p["error"])) if ok else None


def cost_ties(points: list[dict], best: dict, target_error: float) -> list[dict]:
    """The other points that also meet ``target_error`` and whose cost cannot be told from ``best``'s
    (neither is cheaper beyond the noise): the report names them beside the cheapest."""
    return [p for p in points if p is not best and _num(p["cost"]) and _num(p["error"])
            and _hi(p, "error") <= target_error
            and not clearly_below(best, p, "cost") and not clearly_below(p, best, "cost")]


def groups(points: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for p in points:
        out.setdefault(p["group"], []).append(p)
    return out
