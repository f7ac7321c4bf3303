"""The compiled paths compute what the Python path computes.

Three ways to run a sample: the whole loop compiled (reduced plant, built-in laws), the
plant stepped from Python with the laws compiled, and the laws called as Python objects
(how every plug-in runs).  They must agree to 1e-12 (measured: bit-identical; the
references of a quintic move may differ in the last bit, numba evaluating τ³ by
multiplication where CPython calls pow)."""
import numpy as np
import pytest

import validation.run.loop as loop
from reduced_model import ReducedPlant
from validation.run.loop import build, run_scenario, simulate
from validation.run.scenario import scenario_from_mapping

NOISE = {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}
CASES = {
    "pbc": {},
    "pbc+smo-paper": {"observer": {"kind": "smo-paper"}},
    "pbc+smo-bl+delay": {"observer": {"kind": "smo-bl"}, "sensors": NOISE | {"delay": 3}},
    "pbc+smo-pos": {"observer": {"kind": "smo-pos"}},
    "pbc+ekf": {"observer": {"kind": "ekf"}},
    "lqr+ekf-pos": {"controller": {"kind": "lqr"}, "observer": {"kind": "ekf-pos"}},
    "pd+limit+noise-disturbance": {
        "controller": {"kind": "pd"}, "torque_limit": 3.0,
        "disturbances": [{"kind": "noise", "target": "tau2", "amplitude": 0.3},
                         {"kind": "sine", "target": "tau1", "amplitude": 0.5, "start": 0.5}]},
    "ct+quintic": {"controller": {"kind": "ct"},
                   "reference": {"kind": "quintic", "move_time": 1.5}},
    "pbc-idealised": {"controller": {"kind": "pbc-idealised"}},
    "mismatch (foreign modal basis)": {"true_params": {"Mp": 0.3},
                                       "observer": {"kind": "smo-paper"}},
    "diverging (Table 1 at 1 ms)": {"arm": "table1"},
    "lab arm (friction, drives, lags)": {"arm": "lab", "observer": {"kind": "smo-paper"}},
}


def scenario(extra):
    base = {"duration": 2.5, "sensors": NOISE, "initial_state": "rest",
            "observer": {"initial_error": [0.1, 5e-3, 0.3, 0.05]}}
    data = base | extra
    if "observer" in extra:
        data["observer"] = base["observer"] | extra["observer"]
    return scenario_from_mapping(data)


def python_objects(s, monkeypatch):
    """The run with the laws called as Python objects (the plug-in path)."""
    with monkeypatch.context() as m:
        m.setattr(loop, "compiled_form", lambda *a, **k: None)
        return run_scenario(s)


def stepped_from_python(s):
    """The run with the laws compiled but the plant stepped from Python."""
    setup = build(s)
    setup.plant.compiled = lambda: None  # hide the plant's compiled form
    return simulate(setup.plant, setup.controller, setup.observer, s, model=setup.model)


@pytest.mark.parametrize("case", list(CASES))
def test_every_path_computes_the_same_run(case, monkeypatch):
    s = scenario(CASES[case])
    fast = run_scenario(s)
    assert fast.timings["compiled_loop"] is True
    for other in (python_objects(s, monkeypatch), stepped_from_python(s)):
        assert other.timings["compiled_loop"] is False
        assert (fast.status, fast.message, fast.names) == (other.status, other.message, other.names)
        assert fast.signals.shape == other.signals.shape
        np.testing.assert_allclose(fast.signals, other.signals, rtol=0, atol=1e-12)
    if case.startswith("diverging"):
        assert fast.status == "diverged" and "exceeds" in fast.message
    assert fast.timings["paths"] == {"loop": "compiled", "controller": "compiled",
                                     "observer": "compiled" if "observer" in CASES[case]
                                     else "none"}


def test_an_observer_failure_ends_the_run_the_same_way_on_every_path(monkeypatch):
    """The EKF's covariance failure is a status with its message, compiled or not."""
    from controllers import ExtendedKalmanFilter
    reset = ExtendedKalmanFilter.reset

    def broken_reset(self, x_hat0):  # a covariance that is not one: S = P + R < 0
        out = reset(self, x_hat0)
        self._P[:] = -np.eye(len(out))
        return out

    monkeypatch.setattr(ExtendedKalmanFilter, "reset", broken_reset)
    s = scenario({"observer": {"kind": "ekf"}})
    fast = run_scenario(s)
    assert fast.timings["compiled_loop"] is True
    for other in (python_objects(s, monkeypatch), stepped_from_python(s)):
        assert (other.status, other.message) == (fast.status, fast.message)
    assert fast.status == "diverged" and fast.end_time == 0.0
    assert fast.message == ("ekf: the covariance update failed (H P Hᵀ + R is not positive "
                            "definite) at t = 0 s")


def test_plugins_and_payload_forces_take_the_python_path():
    s = scenario({"disturbances": [{"kind": "step", "target": "tip_y", "amplitude": 1.0}]})
    r = run_scenario(s)
    assert r.status == "ok" and r.timings["compiled_loop"] is False
    assert r.timings["paths"]["loop"] == "python"
    assert ReducedPlant().compiled() is not None


def test_the_sample_context_is_built_by_field_name():
    """The compiled constructor takes the fields in `CONTEXT_FIELDS` order; `context`
    passes them by name, so a reordered or renamed field cannot shift the others."""
    import inspect

    from validation.run.sample import CONTEXT_FIELDS, context, new_context
    assert list(inspect.signature(new_context.py_func).parameters) == [
        name for name, _ in CONTEXT_FIELDS]
    with pytest.raises(TypeError, match=r"missing \['Ts'.*unknown \['ts'\]"):
        context(**{name: None for name, _ in CONTEXT_FIELDS if name != "Ts"}, ts=1e-3)


def _two_args(a, b):
    return a + b


@pytest.mark.parametrize("role", ["controller", "observer", "plant"])
def test_a_kernel_of_the_wrong_signature_fails_at_registration(role):
    """Issue 55: a kernel whose arguments do not match its role's signature is refused
    when its pointer is made — a `TypeError` naming the kernel and the signature — never
    called with the wrong arguments.  Known good: the idle controller of
    `CompiledLaw`'s example registers."""
    from numba import njit

    from controllers import CONTROLLER_SIGNATURE, OBSERVER_SIGNATURE, CompiledLaw
    from reduced_model import ArmModel
    from reduced_model.contract import PLANT_SIGNATURE, kernel_pointer
    signature = {"controller": CONTROLLER_SIGNATURE, "observer": OBSERVER_SIGNATURE,
                 "plant": PLANT_SIGNATURE}[role]
    wrong = njit(cache=False)(_two_args)
    with pytest.raises(TypeError, match=r"kernel _two_args does not take the signature"):
        if role == "plant":
            kernel_pointer(wrong, signature)
        else:
            CompiledLaw.of(wrong, signature, ArmModel())

    @njit(cache=False)
    def idle(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
        tau[0] = tau[1] = 0.0
        return 2
    assert CompiledLaw.of(idle, CONTROLLER_SIGNATURE, ArmModel()).pointer.kernel is idle
