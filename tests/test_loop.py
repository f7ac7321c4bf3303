"""The closed loop on both plants: the issue's acceptance bounds, the plant swap,
divergence and failure as results, noise, delay, saturation, disturbances, storage."""
import inspect

import numpy as np
import pytest

from validation.run import loop, metrics
from validation.run.config import ConfigError
from validation.run.loop import build, run_scenario, simulate
from validation.run.results import RunResult
from validation.run.scenario import scenario_from_mapping

# The observer starts 0.1 rad, 5 mm and 0.3 rad/s off, and the sensors are noisy, so that
# "converges" means something.
OBSERVED = {
    "initial_error": [0.1, -0.1, 5e-3, 0.0, -5e-3, 0.0, 0.3, -0.3, 0.0, 0.0, 0.0, 0.0],
}
NOISE = {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}


def scenario(**overrides):
    data = {}
    for key, value in overrides.items():
        node = data
        *path, last = key.split("__")
        for part in path:
            node = node.setdefault(part, {})
        node[last] = value
    return scenario_from_mapping(data)


def r_params(result):
    from reduced_model import ArmParameters
    return ArmParameters.from_mapping(result.config["nominal_params"])


def track_after(result, t0=2.0):
    m = metrics.tracking(result, t0)
    return max(m["track_max_1"], m["track_max_2"])


def test_pbc_true_state_on_reduced_plant():
    r = run_scenario(scenario())
    assert r.status == "ok" and r.end_time == pytest.approx(20.0)
    # The bound is 0.02 rad after 2 s; measured 0.0054 / 0.0089.
    assert track_after(r) <= 0.02
    d = metrics.deflection(r, 2.0)
    # Bounded deflection: the start from rest (reference at 0.6 and 1.3 rad/s) bends
    # link 1 by 8.5 cm; after 2 s it stays below 2.5 cm (measured 1.3 / 1.6 cm).
    assert max(d["defl_max_1"], d["defl_max_2"]) < 0.1
    late = np.abs(r.select(["tip_defl1", "tip_defl2"])[:, r.time >= 2.0]).max()
    assert late < 0.025


# States whose estimate converges by `metrics.convergence_tolerances` (the noise floor,
# the paper's bounds, or 10 % of the state's RMS).  The sign observers' discrete band on
# the modal positions (Ts·L_P = 5e-4 m) is far above the 1e-5 m floor: q12, q21, q22 and
# their rates never converge with smo-paper and smo-pos (measured); the boundary layer
# removes the chatter and every state converges (measured ≤ 0.06 s).
CONVERGING = {"smo-paper": ("theta1", "theta2", "theta1_dot", "theta2_dot"),
              "smo-bl": ("theta1", "theta2", "q11", "q12", "q21", "q22", "theta1_dot",
                         "theta2_dot", "q11_dot", "q12_dot", "q21_dot", "q22_dot"),
              "smo-pos": ("theta1", "theta2", "theta1_dot", "theta2_dot")}


@pytest.mark.parametrize("observer", ["smo-paper", "smo-bl", "smo-pos"])
def test_pbc_with_each_smo_on_reduced_plant(observer):
    r = run_scenario(scenario(observer__kind=observer, observer__initial_error=OBSERVED[
        "initial_error"], **{f"sensors__{k}": v for k, v in NOISE.items()}))
    assert r.status == "ok"
    assert track_after(r) <= 0.03  # the bound with the observer in the loop
    from validation.run.laws import nominal_model
    est = metrics.estimation(r, 2.0, nominal_model(r_params(r), (2, 2)))
    # Converges: 1 s is the paper's "rapidly" (the convergence claim's bound); measured
    # 0.007–0.19 s for the rates and 0.06–0.08 s for the angles.
    for state in CONVERGING[observer]:
        assert 0.0 <= est[f"est_conv_{state}"] < 1.0, (state, est[f"est_conv_{state}"])
    for state in ("theta1", "theta2"):
        # Not converged at t = 0: the angles start 0.1 rad off, five times their 0.02 rad
        # tolerance (the paper's bound), and the first full 0.1 s window holds it.
        assert est[f"est_conv_{state}"] > 0.05
    # After 2 s the angle estimates stay within the paper's 0.02 rad by far: the sign
    # band Ts·L_P = 1e-3 rad plus noise (measured ≤ 1.32e-3 rad).
    assert max(est["est_max_theta1"], est["est_max_theta2"]) < 5e-3
    # The estimate is far better than x̂ ≡ 0 on the angles and joint rates (error / signal
    # RMS measured ≤ 4e-4 and ≤ 0.023; x̂ ≡ 0 gives 1).
    for state in ("theta1", "theta2"):
        assert est[f"est_to_signal_{state}"] < 1e-2
    for state in ("theta1_dot", "theta2_dot"):
        assert est[f"est_to_signal_{state}"] < 0.1


@pytest.mark.parametrize("observer", ["none", "smo-paper", "smo-bl", "smo-pos"])
def test_same_scenarios_run_on_the_exudyn_plant(observer):
    r = run_scenario(scenario(plant__kind="exudyn", duration=5.0, observer__kind=observer,
                              **{f"sensors__{k}": v for k, v in NOISE.items()}))
    assert r.status == "ok", r.message
    # 5 s here (20 s under `make test-all`): the FE plant tracks like the reduced one
    # (measured ≤ 0.0101 rad after 2 s for every observer).
    assert track_after(r) <= 0.03
    # The 2+2 modes capture the FE deflection: the part they cannot represent (absolute,
    # mass-weighted RMS over the link [m]) stays below 0.5 % of each link's RMS tip
    # deflection after the start (measured ≤ 1.1e-5 m of 2 cm and 1.7e-6 m of 1.9 mm:
    # 0.05 % and 0.09 %).
    late = r.time > 0.5
    for link in (1, 2):
        scale = np.sqrt(np.mean(np.square(r[f"tip_defl{link}"][late])))
        assert np.all(r[f"proj_res{link}"][late] <= 5e-3 * scale), link


@pytest.mark.slow
@pytest.mark.parametrize("observer", ["none", "smo-paper", "smo-bl", "smo-pos"])
def test_paper_scenario_20s_on_the_exudyn_plant(observer):
    r = run_scenario(scenario(plant__kind="exudyn", observer__kind=observer))
    assert r.status == "ok", r.message
    assert track_after(r) <= 0.03


def test_swapping_the_plant_is_one_word():
    base = {"duration": 0.5, "transient": 0.2}
    a = run_scenario(scenario(**base))
    b = run_scenario(scenario(plant__kind="exudyn", **base))
    assert a.names == b.names and a.status == b.status == "ok"
    source = inspect.getsource(loop.simulate)
    for word in ("Exudyn", "Reduced", ".kind", "isinstance"):
        assert word not in source, f"simulate() branches on the plant ({word!r})"


@pytest.mark.parametrize("overrides, path, text", [
    (dict(plant__kind="exudyn", controller__kind="pbc-idealised"), "controller.kind",
     "two actuators"),
    # Options of the idealised law only: the realisable PBC refuses them and says why.
    (dict(controller__options__kv_flex=5.0), "controller.options.kv_flex",
     "cannot change the realisable PBC's torque"),
    (dict(controller__options__compensate_damping=False),
     "controller.options.compensate_damping", "cannot change"),
    (dict(observer__kind="smo-pos", sensors__modal="none"), "observer.kind", "q11"),
    (dict(observer__kind="smo-paper", sensors__rates=False), "observer.kind", "theta1_dot"),
    (dict(Ts=1.5e-3), "Ts", "whole multiple"),
    (dict(controller__options__kv_joint=[10.0, -5.0]), "controller.options.kv_joint", ">= 0"),
    (dict(controller__kind="pd", controller__options__kp=[-1.0, 1.0]),
     "controller.options.kp", ">= 0"),
    (dict(controller__kind="pd", controller__options__kv_joint=1.0),
     "controller.options.kv_joint", "not an option of pd"),
    (dict(observer__kind="smo-bl", observer__options__l_velocity=[5.0, -2.0]),
     "observer.options.l_velocity", ">= 0"),
    (dict(observer__options__l_position=1.0), "observer.options", "no observer"),
    (dict(controller__kind="fuzzy"), "controller.kind", "fuzzy"),
    (dict(observer__kind="fuzzy"), "observer.kind", "fuzzy"),
    (dict(feedback="estimate"), "feedback", "needs an observer"),
    (dict(nominal_params__L1=0.6), "nominal_params.L1", "must equal"),
    (dict(sensors__modal="gauges", sensors__gauges_link1=[0.1]), "sensors.gauges_link1",
     "gauge"),
    (dict(observer__initial_error=[0.1, 0.2]), "observer.initial_error", "needs 12 values"),
    (dict(duration=2.0, transient=2.0), "transient", "leaves nothing"),
])
def test_bad_combinations_are_rejected_before_simulation(overrides, path, text):
    with pytest.raises(ConfigError) as exc:
        scenario(**overrides)
    assert exc.value.path == path and text in str(exc.value), str(exc.value)


@pytest.mark.parametrize("plant", ["reduced", "exudyn"])
def test_unstable_gains_end_as_diverged(plant):
    # A 500 N m s/rad sampled D-term on joint 2 is far beyond the stability limit.
    r = run_scenario(scenario(plant__kind=plant, controller__kind="pd",
                              controller__options__kd=[8.0, 500.0], duration=2.0,
                              transient=1.0))
    assert r.status == "diverged"
    assert "at t = " in r.message and r.end_time < 0.5
    assert len(r.time) == round(r.end_time / 1e-3) and np.all(np.isfinite(r.signals))


def test_solver_failure_ends_as_failed():
    s = scenario(plant__kind="exudyn", duration=1.0, transient=0.5)
    setup = build(s)
    setup.plant.settings.timeIntegration.newton.absoluteTolerance = 1e-16
    setup.plant.settings.timeIntegration.newton.relativeTolerance = 1e-16
    r = simulate(setup.plant, setup.controller, setup.observer, s, reference=setup.reference,
                 model=setup.model)
    assert r.status == "failed" and "Exudyn solver failed" in r.message
    assert r.end_time < 1.0 and np.all(np.isfinite(r.signals))


def test_noise_is_seeded():
    noisy = dict(duration=0.3, transient=0.1, **{f"sensors__{k}": v for k, v in NOISE.items()})
    a, b = run_scenario(scenario(seed=3, **noisy)), run_scenario(scenario(seed=3, **noisy))
    c = run_scenario(scenario(seed=4, **noisy))
    np.testing.assert_array_equal(a.signals, b.signals)
    assert not np.array_equal(a["y_theta1"], c["y_theta1"])
    residual = a["y_theta1"] - a["theta1"]
    assert residual.std() == pytest.approx(1e-4, rel=0.15)  # 300 samples: ±8 % at 2σ


def test_measurement_delay_in_whole_samples():
    r = run_scenario(scenario(duration=0.5, transient=0.2, sensors__delay=3))
    np.testing.assert_array_equal(r["y_theta1"][3:], r["theta1"][:-3])
    np.testing.assert_array_equal(r["y_theta1"][:3], r["theta1"][0])


def test_torque_saturation():
    r = run_scenario(scenario(duration=1.0, transient=0.5, torque_limit=2.0))
    assert np.abs(r.select(["tau1", "tau2"])).max() <= 2.0
    assert np.abs(r.select(["tau1_cmd", "tau2_cmd"])).max() > 2.0  # it did saturate


@pytest.mark.parametrize("plant", ["reduced", "exudyn"])
def test_disturbances_reach_the_plant(plant):
    dist = [{"kind": "pulse", "target": "tau1", "amplitude": 3.0, "start": 0.2, "duration": 0.1},
            {"kind": "step", "target": "tip_y", "amplitude": 2.0, "start": 0.5}]
    base = scenario(plant__kind=plant, duration=1.0, transient=0.5)
    hit = scenario(plant__kind=plant, duration=1.0, transient=0.5, disturbances=dist)
    r0, r1 = run_scenario(base), run_scenario(hit)
    t = r1.time
    k = np.arange(len(t))  # edges on the sample grid: samples 200..299 and from 500 on
    np.testing.assert_array_equal(r1["dist_tau1"], np.where((k >= 200) & (k < 300), 3.0, 0.0))
    np.testing.assert_array_equal(r1["dist_tip_y"], np.where(k >= 500, 2.0, 0.0))
    before = t < 0.2
    np.testing.assert_array_equal(r1["theta1"][before], r0["theta1"][before])
    assert np.abs(r1["theta1"] - r0["theta1"]).max() > 1e-3


def test_noise_disturbance_statistics():
    d = [{"kind": "noise", "target": "tau2", "amplitude": 0.5, "bandwidth": 50.0}]
    r = run_scenario(scenario(duration=4.0, disturbances=d))
    # First-order low-passed noise with the given standard deviation; 4000 samples of a
    # 50 Hz process (~400 independent values): ±10 % at 2σ.
    assert r["dist_tau2"].std() == pytest.approx(0.5, rel=0.15)


def test_result_roundtrip(tmp_path):
    r = run_scenario(scenario(duration=0.2, transient=0.1, observer__kind="smo-bl"))
    path = r.save(tmp_path / "run.npz")
    back = RunResult.load(path)
    assert back.names == r.names and back.status == r.status and back.config == r.config
    np.testing.assert_array_equal(back.signals, r.signals)
    t, y = back  # unpacks like a python-control response
    assert y.shape == (len(r.names), len(t))


def test_a_run_holds_blas_to_one_thread_however_the_process_set_it(monkeypatch):
    """A process whose BLAS uses two threads (a notebook's, or a worker forked from one)
    builds and simulates a run with one, as the command line does: a multithreaded product
    sums in another order (a robustness 2e-12 apart on local and Dask workers)."""
    from threadpoolctl import ThreadpoolController, threadpool_limits
    seen = []

    def record(*args, **kwargs):
        seen.append({lib["num_threads"] for lib in ThreadpoolController().info()})
        return real(*args, **kwargs)

    real = loop.Setup
    monkeypatch.setattr(loop, "Setup", record)  # what build constructs last, inside it
    with threadpool_limits(limits=2):
        outside = {lib["num_threads"] for lib in ThreadpoolController().info()}
        build(scenario(duration=0.01))
        after = {lib["num_threads"] for lib in ThreadpoolController().info()}
    assert outside == after == {2}  # known bad: the process's own count, restored after
    assert seen == [{1}]
