"""Helpers shared by the campaign tests (tests/test_campaign.py, tests/reliability/)."""
import json

import numpy as np

from validation.store import ResultStore


def metrics_table(out) -> dict:
    """metrics.csv as {run id: {metric: value}}, without wall-clock columns; NaN (a metric
    that does not apply, e.g. tracking after a transient longer than the run) becomes the
    string "nan" so that equal tables compare equal.  Asserts there are no duplicate rows."""
    rows = ResultStore(out).metrics()
    ids = [r["run_id"] for r in rows]
    assert len(ids) == len(set(ids)), "duplicate rows in metrics.csv"
    clean = lambda v: "nan" if isinstance(v, float) and np.isnan(v) else v  # noqa: E731
    return {r["run_id"]: {k: clean(v) for k, v in r.items()
                          if k not in ("wall_s", "realtime_factor")} for r in rows}


def campaign_toml(spec: dict) -> str:
    """TOML text of a campaign mapping (scalars, lists, one level of tables, [[sweep]]s
    whose axis tables are written with quoted dotted keys)."""
    def value(v):
        return json.dumps(v)

    lines, tables = [], []
    for key, v in spec.items():
        if isinstance(v, dict):
            tables.append((f"[{key}]", v))
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            tables += [(f"[[{key}]]", t) for t in v]
        else:
            lines.append(f"{key} = {value(v)}")
    for header, table in tables:
        lines += ["", header]
        for key, v in table.items():
            if isinstance(v, dict):
                lines += [f"{key}.{json.dumps(sub)} = {value(x)}" for sub, x in v.items()]
            else:
                lines.append(f"{key} = {value(v)}")
    return "\n".join(lines) + "\n"
