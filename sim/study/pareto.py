"""The Pareto front of measured (cost, error) points, and the cheapest setting for a target error."""

from __future__ import annotations

import math


def _num(v) -> bool:
    return v is not None and isinstance(v, (int, float)) and math.isfinite(v)


def pareto_front(points: list[dict]) -> list[dict]:
    """The points no other point beats on both cost and error (lower is better for both), by cost.

    A point is dominated when another has ``cost <=`` and ``error <=`` with at least one strict.
    Points without a finite cost and error are left out.
    """
    pts = [p for p in points if _num(p["cost"]) and _num(p["error"])]
    front = [p for p in pts if not any(
        q["cost"] <= p["cost"] and q["error"] <= p["error"] and (q["cost"] < p["cost"] or q["error"] < p["error"])
        for q in pts)]
    return sorted(front, key=lambda p: (p["cost"], p["error"]))


def cheapest_for(points: list[dict], target_error: float) -> dict | None:
    """The lowest-cost point whose error is at most ``target_error`` (ties: the lower error)."""
    ok = [p for p in points if _num(p["cost"]) and _num(p["error"]) and p["error"] <= target_error]
    return min(ok, key=lambda p: (p["cost"], p["error"])) if ok else None


def groups(points: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for p in points:
        out.setdefault(p["group"], []).append(p)
    return out
