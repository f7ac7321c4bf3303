"""The Python path a notebook takes: a law given as a class, a plug-in that cannot be
imported said with where it is looked for, a result drawn in the paper's Figs. 3–4 layout
and handed to pandas."""
import sys

import matplotlib
import numpy as np
import pytest

from validation import ConfigError, run_scenario, scenario_from_mapping

matplotlib.use("Agg")


class NotebookPD:
    """A PD defined where the user works (here: this test module)."""

    def __init__(self, model, *, Ts):
        pass

    def __call__(self, t, x, ref):
        n = x.shape[0] // 2
        theta_d, dtheta_d, _ = ref(t)
        return 30.0 * (theta_d - x[:2]) + 10.0 * (dtheta_d - x[n:n + 2])


def test_a_law_given_as_a_class_runs_by_its_import_path():
    s = scenario_from_mapping({"duration": 0.05, "controller": {"kind": NotebookPD}})
    assert s.controller.kind == f"{__name__}:NotebookPD"
    assert run_scenario(s).status == "ok"


@pytest.mark.parametrize("kind, text", [
    (NotebookPD(None, Ts=1e-3),
     "controller.kind: give the class NotebookPD, not an instance of it"),
    (3, "controller.kind: give a class or its name, got 3")])
def test_what_is_no_law_says_what_to_give(kind, text):
    with pytest.raises(ConfigError) as err:
        scenario_from_mapping({"controller": {"kind": kind}})
    assert str(err.value).startswith(text)


def test_a_plugin_that_cannot_be_imported_says_where_it_is_looked_for(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError) as err:
        scenario_from_mapping({"controller": {"kind": "mylab_absent.control:PD"}})
    assert "No module named 'mylab_absent'" in str(err.value)
    assert f"installed, on PYTHONPATH, or in the directory the command runs from, here " \
           f"{tmp_path}" in str(err.value)


@pytest.fixture(scope="module")
def both():
    return [run_scenario(scenario_from_mapping({"duration": 0.2, "plant": {"kind": kind},
                                                "controller": {"kind": "pd"}}))
            for kind in ("reduced", "exudyn")]


def test_plot_draws_figs_3_and_4_with_the_other_plant_overlaid(both):
    reduced, truth = both
    fig = truth.plot(reduced)
    assert len(fig.axes) == 6
    labels = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
    assert {"truth plant (Exudyn)", "reduced plant", "reference, eq. (37)"} <= set(labels)
    assert [ax.get_ylabel() for ax in fig.axes[::2]] == ["θ₁ [rad]", "θ₁ − θ₁,d [mrad]",
                                                        "tip deflection 1 [mm]"]


def test_to_dataframe_names_its_columns_or_says_how_to_get_pandas(both, monkeypatch):
    result = both[0]
    try:
        import pandas  # noqa: F401
    except ImportError:
        pass
    else:
        frame = result.to_dataframe()
        assert list(frame.columns) == list(result.names) and frame.index.name == "t"
        assert np.array_equal(frame["theta1"].to_numpy(), result["theta1"])
    monkeypatch.setitem(sys.modules, "pandas", None)  # as if it were not installed
    with pytest.raises(ImportError, match="needs pandas, which flexarm-validation does not "
                                          "install: pip install pandas"):
        result.to_dataframe()
