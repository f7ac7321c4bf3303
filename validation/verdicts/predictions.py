"""A stability map's predictions: computed beside its runs, kept in its folder.

The predicted limit of every case (`validation.verdicts.sampled`: ~1 s of python-control
a linearisation, 18 for the paper's 42 cases) is computed by a thread of the map's
process while the workers run the map (`Predictions`), and kept in ``predictions.json``
in the map's folder, so that a report of the folder reads them instead of linearising
every case again (the paper's 18 linearisations: 16 s of a 32 s report of its folder).

A prediction is stored by its case's key (`prediction_key`) with the code that made it
(`validation.batch.fingerprint.computed_by`: the project files `MADE_BY` can import and
the installed packages they reach, not the reports': editing a report keeps them);
predictions made by other code are not read.  This module imports nothing heavy: a
report that reads them does not load python-control.
"""
from __future__ import annotations

import json
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from ..batch.fingerprint import computed_by
from ..run.processes import between_forks
from ..run.results import write_atomic

__all__ = ["PREDICTIONS", "PROBE_TS", "MADE_BY", "prediction_key", "Predictions",
           "write_predictions", "read_predictions"]

#: The file in a stability map's folder.
PREDICTIONS = "predictions.json"
#: The modules that compute a prediction and key it: the code a stored one depends on.
MADE_BY = ("validation.verdicts.sampled", "validation.verdicts.predictions")
#: The period a case's law is first built at, to see whether it can be linearised and
#: what it applies (the paper's period; the prediction then builds it at every period
#: it scans).
PROBE_TS = 1e-3


def prediction_key(config: dict) -> str:
    """A case's key: its mapping without what its linearisation does not depend on — the
    period (the law is first built at `PROBE_TS`), the plant's step, the run's name, and
    the observer (the loop linearised is the controller's fed the true state) — so that
    the map's case and the same case rebuilt from any of its stored runs (the report's),
    and the cases of one controller with each observer, share one linearisation, computed
    once per process (~1 s a case: the paper's map has 42 cases and 18 linearisations)."""
    plant = {k: v for k, v in config["plant"].items() if k != "step"}
    data = {k: v for k, v in config.items() if k != "name"}
    return json.dumps(dict(data, Ts=PROBE_TS, plant=plant, observer={"kind": "none"},
                           feedback="auto"), sort_keys=True)


def _made_by() -> str:
    return computed_by(MADE_BY)


def write_predictions(folder, periods: dict[str, float]) -> None:
    """Keep ``periods`` ({`prediction_key`: predicted period [s]}) in ``folder``, beside
    those kept there before by this code (a map of other cases into the same folder)."""
    text = json.dumps({"made_by": _made_by(), "periods": {**read_predictions(folder),
                                                          **periods}}, sort_keys=True)
    write_atomic(Path(folder) / PREDICTIONS, lambda fh: fh.write(text))


def read_predictions(folder) -> dict[str, float]:
    """The periods kept in ``folder`` by this code ({} if none, if unreadable or if made
    by other code)."""
    try:
        data = json.loads((Path(folder) / PREDICTIONS).read_text())
        periods = data["periods"] if data["made_by"] == _made_by() else {}
        return {str(k): float(v) for k, v in periods.items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


class Predictions:
    """The predicted limit of each of ``configs`` (cases' resolved mappings) by
    ``predict`` (config → period), computed by a thread of this process in ``order``
    (the map's: the cases fed the true state first, whose searches start from their
    prediction); ``futures[i]`` is case i's.  No worker is forked while the thread is
    inside ``predict`` (`validation.run.processes.between_forks`)."""

    def __init__(self, configs: list[dict], order: list[int], predict) -> None:
        def guarded(config):
            with between_forks():  # no fork while this thread is inside a library
                return predict(config)
        self._thread = ThreadPoolExecutor(1, thread_name_prefix="stability-prediction")
        self.futures = {i: self._thread.submit(guarded, configs[i]) for i in order}
        self._keys = [prediction_key(c) for c in configs]

    def close(self, *, finish: bool) -> None:
        """Wait for every prediction (``finish``), or drop those not started."""
        self._thread.shutdown(wait=finish, cancel_futures=not finish)

    def periods(self) -> dict[str, float]:
        """{`prediction_key`: predicted period} of every case (after `close`)."""
        return {key: self.futures[i].result() for i, key in enumerate(self._keys)}

