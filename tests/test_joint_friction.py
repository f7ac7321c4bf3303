"""Joint friction with stiction on both plants (issue 41's cases, its tolerances): a torque
below breakaway holds the joint, above it slides, up to breakaway itself (issue 59); sliding
Coulomb friction is a constant opposing torque; viscous friction sets the whole arm's
terminal speed; the energy the arm loses is the friction's work; a regularised friction
model creeps."""
import numpy as np
import pytest

from plant_exudyn import ExudynPlant
from reduced_model import ArmModel, ArmParameters, ReducedPlant

PLANTS = {"reduced": lambda p: ReducedPlant(p), "truth": lambda p: ExudynPlant(p)}


def simulate(plant, torque, duration: float) -> np.ndarray:
    """The truth vectors at every period (from t = 0) with ``torque(t)`` held."""
    plant.reset()
    out = [plant.truth_vector()]
    Ts = plant.Ts
    for k in range(int(round(duration / Ts))):
        plant.advance(np.asarray(torque(k * Ts), float))
        out.append(plant.truth_vector())
    return np.array(out)


def sticky(joint: int, coulomb=0.3, breakaway=0.4) -> ArmParameters:
    return ArmParameters(**{f"coulomb{joint}": coulomb, f"breakaway{joint}": breakaway,
                            f"stribeck_velocity{joint}": 0.01})


def largest_motion(plant, joint: int, torque: float) -> float:
    """max |θ_joint| over 1 s from rest under a constant ``torque`` on that joint."""
    tau = np.zeros(2)
    tau[joint - 1] = torque
    return np.abs(simulate(plant, lambda t: tau, 1.0)[:, joint - 1]).max()


@pytest.mark.parametrize("kind", PLANTS)
@pytest.mark.parametrize("joint", [1, 2])
def test_below_breakaway_the_joint_holds_above_it_slides(kind, joint):
    # The criterion: ≤ 1e-4 rad in 1 s at 0.8 × breakaway.  Measured: 0 (the
    # reduced plant's exact constraint), 6e-25 and 1e-18 rad (the truth plant's bristle,
    # loaded with the holding torque by the hold: round-off).  Above breakaway (1.2×) it
    # slides 0.056 and 0.16 rad: the same criterion fails by 500×.
    p = sticky(joint)
    assert largest_motion(PLANTS[kind](p), joint, 0.8 * 0.4) <= 1e-4
    assert largest_motion(PLANTS[kind](p), joint, 1.2 * 0.4) > 1e-2


def slide(kind: str, params: ArmParameters, torque) -> np.ndarray:
    """max |θ − θ(0)| of each joint over 5 s from rest under the constant ``torque``."""
    run = simulate(PLANTS[kind](params), lambda t: torque, 5.0)
    return np.abs(run[:, :2] - run[0, :2]).max(axis=0)


#: Both joints with the Stribeck friction of `sticky` (breakaway 0.4 N m).
BOTH = ArmParameters(coulomb1=0.3, breakaway1=0.4, stribeck_velocity1=0.01,
                     coulomb2=0.3, breakaway2=0.4, stribeck_velocity2=0.01)


@pytest.mark.parametrize("kind", PLANTS)
@pytest.mark.parametrize("joint", [1, 2])
@pytest.mark.parametrize("fraction", [0.99, 0.998, 0.999, 0.99999])
def test_up_to_breakaway_a_torque_step_holds_the_joint_for_5_s(kind, joint, fraction):
    """Issue 59: a constant torque just below breakaway holds the joint as the exact stick
    does, to 1e-5 of it.  Bound 1e-6 rad over 5 s (the slide just above breakaway, below,
    is 0.5-2 rad).
    Measured: 0 (reduced), ≤ 1e-15 rad (truth: round-off; its hold loads the stuck
    bristle with the holding torque at each torque step).  Known-bad: the bristle left
    to find the torque through its own transient (before the fix) slid 0.64 rad at
    0.998× (joint 1) and 0.75 rad at 0.999× (joint 2), and let the stator's bristle
    deflect 6.5e-6 rad at 0.99×."""
    torque = np.zeros(2)
    torque[joint - 1] = fraction * 0.4
    assert slide(kind, sticky(joint), torque).max() <= 1e-6


@pytest.mark.parametrize("kind", PLANTS)
def test_both_joints_stuck_at_once_hold_their_torques(kind):
    """Both joints at 0.99999× breakaway, in opposite senses: both hold to 1e-6 rad
    (measured 0 and 1.5e-18 rad; before the fix the truth plant slid 1.6 and 2.8 rad at
    0.999×)."""
    assert slide(kind, BOTH, np.array([0.99999 * 0.4, -0.99999 * 0.4])).max() <= 1e-6


@pytest.mark.parametrize("kind", PLANTS)
@pytest.mark.parametrize("joint", [1, 2])
@pytest.mark.parametrize("fraction", [1.00001, 1.01])
def test_just_above_breakaway_the_joint_slides(kind, joint, fraction):
    """Known-bad of the criterion above: at 1.00001× and 1.01× breakaway the joint breaks
    loose and slides far more than 1e-6 rad (bound 1e-2 rad in 5 s; measured 0.47 and
    0.68 rad (reduced, truth) on joint 1, 2.06 on joint 2 at 1.00001×; 0.76-2.15 rad at
    1.01×).  At breakaway itself round-off decides (the truth plant's joint 1 holds, its
    joint 2 slides): no test sits there."""
    torque = np.zeros(2)
    torque[joint - 1] = fraction * 0.4
    assert slide(kind, sticky(joint), torque)[joint - 1] > 1e-2


def breakaway_period(kind: str, params: ArmParameters, joint: int) -> int:
    """The first period in which ``joint`` has moved 1e-6 rad under a torque ramp on it
    that reaches 0.4 N m at 2 s."""
    torque = np.zeros(2)

    def ramp(t):
        torque[joint - 1] = 0.4 * t / 2.0
        return torque
    run = simulate(PLANTS[kind](params), ramp, 2.5)
    return int(np.argmax(np.abs(run[:, joint - 1] - run[0, joint - 1]) > 1e-6))


@pytest.mark.parametrize("joint", [1, 2])
def test_a_torque_ramp_breaks_the_joint_loose_in_the_same_period_on_both_plants(joint):
    """The ramp crosses breakaway at 2 s; both plants' joints start to move in the same
    period, to 2 periods (1e-3 of τs; measured: 2.031 s on both for joint 1, 2.005 and
    2.006 s for joint 2 — just past breakaway a joint needs a few periods to move 1e-6
    rad).  Known-bad: a breakaway level 1 % higher moves it by 16-20 periods."""
    reduced = breakaway_period("reduced", sticky(joint), joint)
    assert abs(breakaway_period("truth", sticky(joint), joint) - reduced) <= 2
    assert abs(breakaway_period("truth", sticky(joint, breakaway=0.404), joint) - reduced) > 2


def test_a_regularised_friction_model_creeps():
    """Known-bad: Exudyn's regularised Stribeck curve (frictionProportionalZone ≠ 0) has
    no force at zero velocity, so the joint creeps under the torque the bristle holds
    (measured 8e-4 rad in 1 s: 8× the criterion)."""
    plant = ExudynPlant(sticky(1))
    connector = plant.system.joints.friction[0][-1]
    plant.system.mbs.SetObjectParameter(connector, "frictionProportionalZone", 1e-3)
    assert largest_motion(plant, 1, 0.8 * 0.4) > 1e-4


@pytest.mark.parametrize("kind", PLANTS)
def test_sliding_coulomb_friction_is_a_constant_opposing_torque(kind):
    """τ1 = 1.5 N m against τc = 0.5 moves the arm as τ1 = 1.0 without friction, to 1 %
    of the travel (measured: 0 on the reduced plant, where the sliding law is applied
    exactly; 2.6e-4 on the truth plant).  Known-bad: a friction level 10 % off (0.45 N m)
    misses by ~5 % of the travel."""
    reference = simulate(PLANTS[kind](ArmParameters()), lambda t: [1.0, 0.0], 1.0)
    travel = abs(reference[-1, 0] - reference[0, 0])

    def miss(coulomb):
        run = simulate(PLANTS[kind](ArmParameters(coulomb1=coulomb)), lambda t: [1.5, 0.0], 1.0)
        return np.abs(run[:, :2] - reference[:, :2]).max() / travel

    assert miss(0.5) <= 0.01
    assert miss(0.45) > 0.01


@pytest.mark.parametrize("kind", PLANTS)
def test_viscous_friction_sets_the_whole_arms_terminal_speed(kind):
    """Angular momentum about the base: dL/dt = τ1 − b1 θ̇1 (joint 2's friction is
    internal), so the arm spins up to θ̇1 = τ1/b1 = 0.1 rad/s, within 1 % (measured
    4.5e-4 after 6 s, five time constants of ~1.2 s; b2 damps the outer link's swing).
    Known-bad: τ1/(b1 + b2), counting joint 2's internal friction, is 30 % off."""
    plant = PLANTS[kind](ArmParameters(viscous1=5.0, viscous2=2.0))
    run = simulate(plant, lambda t: [0.5, 0.0], 6.0)
    rate = run[-1, plant.state_size // 2]
    assert rate == pytest.approx(0.5 / 5.0, rel=0.01)
    assert rate != pytest.approx(0.5 / 7.0, rel=0.01)


@pytest.mark.parametrize("kind", PLANTS)
def test_the_energy_the_arm_loses_is_the_frictions_work(kind):
    """A torque cycle τ1 = 2 sin(πt) on an arm whose only loss is joint 1's Coulomb
    friction: W_motor − E(end) = ∮τ_f dθ = τc × the path θ1 travelled.  W_motor is exact
    under the hold (τ constant over each period: Σ τ_k Δθ_k); E is the reduced model's
    energy of the state (the truth plant's projected on its modes), starting from rest.
    Measured: 1e-6 (reduced) and 5e-7 (truth) of ∮τ_f dθ; bound 1e-4.  Known-bad: the
    default arm's link damping (2e-3 N m² s) dissipates another 3e-4 of it."""
    def imbalance(damping):
        p = ArmParameters(coulomb1=0.5, bending_damping1=damping, bending_damping2=damping)
        model = ArmModel(p)
        torque = lambda t: [2.0 * np.sin(np.pi * t) if t < 2.0 else 0.0, 0.0]  # noqa: E731
        run = simulate(PLANTS[kind](p), torque, 3.0)
        theta, n = run[:, 0], model.n
        work = sum(torque(k * 1e-3)[0] * d for k, d in enumerate(np.diff(theta)))
        friction = 0.5 * np.abs(np.diff(theta)).sum()
        x = run[-1, :2 * n]
        energy = model.kinetic_energy(x[:n], x[n:]) + model.potential_energy(x[:n])
        return abs((work - energy) / friction - 1.0)

    assert imbalance(0.0) <= 1e-4
    assert imbalance(2e-3) > 1e-4
