"""The sweep's table: one row per trial, written as Parquet with pyarrow."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, Iterable, List

#: The columns every table has, first.
FIRST = ["id", "outcome", "reason", "self_intersections", "attempts", "trial_wall_s",
         "trial_cpu_s", "dir"]


def flatten(fit: Dict[str, Any]) -> Dict[str, Any]:
    """Every scalar of a fit report under its dotted key: ``run.wall_s``,
    ``panels.<panel>.warp.max_percent``, ``girths.<girth>.ease_cm``,
    ``contact_force_n.0``…; a list of strings (``warnings``) as one text,
    lines apart."""
    out: Dict[str, Any] = {}

    def walk(prefix: str, v: Any) -> None:
        if isinstance(v, dict):
            for k, x in v.items():
                walk(f"{prefix}.{k}" if prefix else str(k), x)
        elif isinstance(v, list):
            if prefix == "panels" and all(isinstance(p, dict) and "name" in p for p in v):
                for p in v:
                    walk(f"panels.{p['name']}", {k: x for k, x in p.items() if k != "name"})
            elif all(isinstance(x, str) for x in v):
                out[prefix] = "\n".join(v)
            else:
                for i, x in enumerate(v):
                    walk(f"{prefix}.{i}", x)
        else:
            out[prefix] = v

    walk("", fit)
    return out


def rows_of(results: Iterable[Dict[str, Any]], axes: List[str]) -> List[Dict[str, Any]]:
    """The table's rows from the trials' results: the axes' values under
    their keys, the outcome, then the fit report flattened (under ``fit.KEY``
    where KEY is also an axis)."""
    rows = []
    for r in results:
        row = {k: r.get(k) for k in FIRST}
        for a in axes:
            v = r.get(a)
            row[a] = v
        for k, v in flatten(r.get("fit") or {}).items():
            row[f"fit.{k}" if k in row else k] = v
        rows.append(row)
    return rows


def write_table(results: List[Dict[str, Any]], axes: List[str], path: Path) -> Path:
    """Writes the rows as Parquet at ``path`` (atomically); returns ``path``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = rows_of(results, axes)
    cols: List[str] = []
    for r in rows:
        cols.extend(k for k in r if k not in cols)
    data = {}
    for c in cols:
        vals = [r.get(c) for r in rows]
        kinds = {type(v) for v in vals if v is not None}
        if kinds == {int, float}:
            vals = [None if v is None else float(v) for v in vals]
        elif len(kinds) > 1:
            vals = [None if v is None else str(v) for v in vals]
        data[c] = pa.array(vals)
    table = pa.table(data) if data else pa.table({"id": pa.array([], pa.string())})
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)
    return path
