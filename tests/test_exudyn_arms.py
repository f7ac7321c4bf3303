"""The truth plant for any arm of 1–4 links, rigid or flexible, horizontal or in gravity,
against independent references: the Euler–Bernoulli frequency equation of a link on a
free hub with a tip mass, the cantilever's sag under its own weight, the rigid-body
dynamics of the reduced plant (exact for rigid links), and a three-link arm's exact
kinematics."""
import exudyn as exu
import numpy as np
import pytest
import scipy.optimize

from plant_exudyn import ExudynPlant, Mesh, build_arm, natural_frequencies, simulation_settings
from reduced_model import ArmParameters, FieldError, ReducedPlant
from reduced_model.arm import Joint, Link, Payload
from reduced_model.contract import true_state_from_vector

G = 9.81


def flexible(L, rho, EI, **kw):
    """A flexible link (4 assumed modes, no damping unless given)."""
    return Link(length=L, mass_per_length=rho, bending_stiffness=EI,
                bending_damping=kw.pop("bending_damping", 0.0), modes=kw.pop("modes", 4), **kw)


def rigid(L, rho, **kw):
    return Link(length=L, mass_per_length=rho, bending_stiffness=0.0, bending_damping=0.0,
                modes=0, **kw)


# --- a single flexible link on a free hub: the Euler–Bernoulli frequency equation ----------------
#: A lab-size rotary flexible link: 0.6 m, 0.5 kg/m, EI = 2 N m², hub 0.02 kg m², tip 0.1 kg.
L1, RHO1, EI1, JH1, MP1 = 0.6, 0.5, 2.0, 0.02, 0.1


def euler_bernoulli_frequencies(L, rho, EI, J_hub, M_tip, J_tip, count=2):
    """The first ``count`` non-zero natural frequencies [Hz] of a uniform Euler–Bernoulli
    beam clamped to a hub of inertia ``J_hub`` turning freely about the beam's root, with
    a tip mass ``M_tip`` and tip inertia ``J_tip``: roots of the characteristic
    determinant of W = a₁ sin βx + a₂ (cos βx − cosh βx) + a₃ sinh βx (W(0) = 0) under

        EI W''(0) = −J_hub ω² W'(0),  EI W''(L) = J_tip ω² W'(L),  EI W'''(L) = −M_tip ω² W(L),

    with ω² = EI β⁴ / ρ (from the variation of the hub's, beam's and tip's energies)."""
    def det(beta):
        b, bL = beta, beta * L
        s, c, sh, ch = np.sin(bL), np.cos(bL), np.sinh(bL), np.cosh(bL)
        w2 = EI * b**4 / rho
        W = np.array([s, c - ch, sh])
        W1 = b * np.array([c, -s - sh, ch])
        W2 = b**2 * np.array([-s, -c - ch, sh])
        W3 = b**3 * np.array([-c, s - sh, ch])
        root = EI * b**2 * np.array([0.0, -2.0, 0.0]) + J_hub * w2 * b * np.array([1.0, 0.0, 1.0])
        A = np.array([root, EI * W2 - J_tip * w2 * W1, EI * W3 + M_tip * w2 * W])
        return np.linalg.det(A) / (b**6 * ch**2)  # scaled: bounded as β grows

    grid = np.linspace(0.05, 40.0 / L, 40000)
    values = np.array([det(b) for b in grid])
    roots = [scipy.optimize.brentq(det, grid[i], grid[i + 1], xtol=1e-15)
             for i in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))]
    return np.array(roots[:count]) ** 2 * np.sqrt(EI / rho) / (2 * np.pi)


def single_link(J_tip=0.0, gravity=(0.0, 0.0), EI=EI1):
    return ArmParameters(links=(flexible(L1, RHO1, EI, hub_mass=1.0, hub_inertia=JH1),),
                         payload=Payload(mass=MP1, inertia=J_tip), gravity=gravity)


@pytest.mark.parametrize("J_tip", [0.0, 2e-4], ids=["point-mass", "rigid-payload"])
def test_single_link_frequencies_are_the_euler_bernoulli_roots(J_tip):
    """The free arm's first two bending frequencies (joint free, θ = 0) against the
    frequency equation solved here (reference: 4.17288, 15.94760 Hz for the point mass).
    Measured errors, point mass: ANCF 4 el (the default mesh) 5.3e-6 and 6.5e-4, ANCF 16
    el 2.4e-8 and 2.7e-6, GE 64 el 3.6e-5 and 4.9e-4 (rigid payload: 5.2e-6 and 5.4e-4,
    8.8e-8 and 2.2e-6, 3.5e-5 and 4.4e-4)."""
    reference = euler_bernoulli_frequencies(L1, RHO1, EI1, JH1, MP1, J_tip)
    # Known-bad: the same link clamped (an infinite hub inertia) or without its tip
    # mass is 3.4-51 % away, far outside the bounds below.
    for other in (euler_bernoulli_frequencies(L1, RHO1, EI1, 1e9, MP1, J_tip),
                  euler_bernoulli_frequencies(L1, RHO1, EI1, JH1, 0.0, J_tip)):
        assert np.abs(other / reference - 1).max() > 0.01
    arm = single_link(J_tip)
    errors = {}
    for mesh in (Mesh(), Mesh(elements_per_link=16), Mesh("geometrically_exact", 64)):
        f = natural_frequencies(arm, mesh, joints="free", n=2)
        errors[mesh] = np.abs(f / reference - 1)
    # The 0.1 %: met by the default mesh already, by 16 ANCF elements with two
    # orders of magnitude to spare (the dense eigen-solver's noise is ~1e-7).
    assert errors[Mesh()].max() < 1e-3
    assert errors[Mesh(elements_per_link=16)].max() < 1e-5
    assert errors[Mesh("geometrically_exact", 64)].max() < 1e-3


# --- gravity: the cantilever's sag ----------------------------------------------------------------
def static_cantilever(arm, mesh):
    """The arm with its joint locked at θ = 0, solved statically (Exudyn's Newton static
    solver, 5 load steps): (tip node position, holding torque on the joint [N m])."""
    system = build_arm(arm, mesh, lock_joints=True)
    mbs = system.mbs
    settings = simulation_settings(step=1e-3)
    settings.staticSolver.verboseMode = 0
    settings.staticSolver.numberOfLoadSteps = 5
    # residuals in N: 1e-7 N moves the tip by ~1e-9 m of the 7.5 mm sag
    settings.staticSolver.newton.absoluteTolerance = 1e-7
    settings.staticSolver.newton.relativeTolerance = 1e-8
    assert mbs.SolveStatic(settings)
    lock = next(i for i in range(mbs.systemData.NumberOfObjects())
                if mbs.GetObject(i)["objectType"] == "JointGeneric")  # joint 1: the first
    tip = mbs.GetNodeOutput(system.links[0].nodes[-1], exu.OutputVariableType.Position)
    torque = mbs.GetObjectOutput(lock, exu.OutputVariableType.TorqueLocal)[2]
    return np.asarray(tip[:2]), -torque


def test_a_link_in_gravity_sags_as_a_cantilever():
    """A single link held horizontal in a vertical plane (joint locked, static solve):
    tip sag w = ρgL⁴/(8EI) + M_p gL³/(3EI) (linear beam theory) and holding torque = the
    static moment of its weight about the joint, shortened by the foreshortening of the
    bent link (the FE beam is geometrically exact: its tip moves in by ½∫w'², 5.5e-5 m
    here).  EI = 20 N m²: a 1.25 % sag, small enough for linear theory to hold to
    (w/L)² ~ 1.6e-4."""
    EI = 20.0
    arm = single_link(gravity=(0.0, -G), EI=EI)
    sag = RHO1 * G * L1**4 / (8 * EI) + MP1 * G * L1**3 / (3 * EI)
    moment = RHO1 * G * L1**2 / 2 + MP1 * G * L1
    # The foreshortened moment: x(s) = s − ½∫₀ˢ w'² of the linear cantilever's slope
    # w' = q/(6EI)(s³ − 3Ls² + 3L²s) + P/(2EI)(2Ls − s²), q = ρg, P = M_p g.
    s = np.linspace(0.0, L1, 20001)
    slope = (RHO1 * G / (6 * EI) * (s**3 - 3 * L1 * s**2 + 3 * L1**2 * s)
             + MP1 * G / (2 * EI) * (2 * L1 * s - s**2))
    inward = np.concatenate([[0.0], np.cumsum(0.5 * (slope[1:]**2 + slope[:-1]**2) / 2
                                                * np.diff(s))])
    shortened = moment - RHO1 * G * np.trapezoid(inward, s) - MP1 * G * inward[-1]
    tips = {n: static_cantilever(arm, Mesh(elements_per_link=n)) for n in (16, 32)}
    (tip16, torque16), (tip32, torque32) = tips[16], tips[32]
    assert abs(tip16[1] - tip32[1]) < 1e-6 * sag  # converged: measured 1.6e-8 relative
    # Measured: sag 1.39e-4 below linear theory (its geometric nonlinearity, ~(w/L)²).
    assert -tip16[1] == pytest.approx(sag, rel=5e-3)
    assert -tip16[1] == pytest.approx(sag, rel=5e-4)
    assert L1 - tip16[0] == pytest.approx(inward[-1], rel=1e-2)
    # Measured: 7.29e-5 below ρgL²/2 + M_p gL, the foreshortened moment to 1.9e-8
    # (what is left: the axial strain and fourth-order terms).
    assert torque16 == pytest.approx(moment, rel=2e-4)
    assert abs(torque16 / moment - 1) > 3e-5  # the foreshortening is resolved…
    assert torque16 == pytest.approx(shortened, rel=1e-6)  # …and it is the whole gap


def test_a_vertical_arm_starts_where_told():
    """No hidden static solve: in gravity the arm starts undeformed at the given angles
    (the sag comes from the run)."""
    arm = single_link(gravity=(0.0, -G))
    plant = ExudynPlant(arm)
    x0 = np.zeros(plant.state_size)
    x0[0] = 0.2
    plant.reset(x0)
    truth = plant.truth()
    assert truth.theta[0] == pytest.approx(0.2, abs=1e-14)
    np.testing.assert_allclose(truth.q, 0.0, atol=1e-14)
    for _ in range(20):
        plant.step(np.zeros(1))
    assert abs(plant.truth().tip_deflections[0]) > 1e-4  # it falls and bends (1.5 mm)


# --- rigid links: one body with the link's mass, first moment and inertia -----------------------
RIGID_ARM = ArmParameters(
    links=(rigid(0.5, 2.0, hub_mass=1.0, hub_inertia=0.05, stator_mass=0.3,
                 stator_inertia=0.01),
           rigid(0.4, 1.5, hub_mass=0.5, hub_inertia=0.02)),
    payload=Payload(mass=0.2, inertia=1e-3), gravity=(0.0, -G))


def pulses(t):
    return np.array([4.0 * (0.2 <= t < 0.5) - 2.0 * (0.6 <= t < 0.7),
                     1.5 * (0.1 <= t < 0.3) - 1.0 * (0.5 <= t < 0.8)])


def joint_angles(plant, torque, seconds=1.0, x0=None):
    plant.reset(x0)
    out = []
    for k in range(round(seconds / plant.Ts)):
        plant.step(torque(k * plant.Ts))
        out.append(plant.truth_vector()[:plant.n_joints].copy())
    return np.array(out)


def test_rigid_links_move_as_the_reduced_plant():
    """Two rigid links in a vertical plane under torque pulses over 1 s (a 3 rad swing):
    the FE bodies (each link's hub, ρL at L/2 with ρL³/12 about its centre, stator or
    payload) against the reduced plant, whose rigid-link dynamics are exact (RK4 at
    0.1 ms: 2e-14 rad from 50 µs).  The FE error is the solver's: second order in the
    step (measured max |Δθ| at 1, 0.5, 0.25, 0.125, 0.0625 ms: 9.3e-5, 2.3e-5, 5.8e-6,
    1.5e-6, 3.6e-7 rad) with a Newton tolerance of 1e-9; the default 1e-6 leaves
    ~1.4e-6 rad."""
    x0 = np.array([0.3, -0.4, 0.0, 0.0])
    reference = joint_angles(ReducedPlant(RIGID_ARM, step=1e-4), pulses, x0=x0)
    errors = [np.abs(joint_angles(ExudynPlant(RIGID_ARM, step=h, newton_tolerance=1e-9),
                                  pulses, x0=x0) - reference).max() for h in (5e-4, 2.5e-4)]
    assert errors[1] < 1e-5
    assert 3.5 < errors[0] / errors[1] < 4.5  # second order: the solver's own error
    # Known-bad: a 1.5 % heavier second link moves the reduced plant 2.2e-2 rad away.
    heavier = RIGID_ARM.replace(rho2=1.515)
    assert np.abs(joint_angles(ReducedPlant(heavier, step=1e-4), pulses, x0=x0)
                  - reference).max() > 100 * errors[1]


# --- what the plant reports for N links ----------------------------------------------------------
RIGID_FLEXIBLE = ArmParameters(
    links=(rigid(0.4, 2.0, hub_mass=1.0, hub_inertia=0.05, stator_mass=0.2,
                 stator_inertia=0.01),
           flexible(0.5, 1.0, 10.0, modes=2, hub_mass=0.5, hub_inertia=0.02,
                    bending_damping=2e-3)),
    payload=Payload(mass=0.1, inertia=5e-4))


@pytest.mark.parametrize("element", ["ancf", "geometrically_exact"])
def test_truth_vector_of_a_rigid_flexible_arm(element):
    """[θ, q, θ̇, q̇, tips, tip deflections, residuals, motors] for a rigid link 1 (no
    modal coordinates, no deflection) and a flexible link 2, placed at a deflected,
    moving state: the tips where the geometry puts them, the modal state recovered."""
    plant = ExudynPlant(RIGID_FLEXIBLE, mesh=Mesh(element, 8 if element == "ancf" else 32))
    assert plant.state_size == 2 * (2 + 2)
    x0 = np.array([0.4, -0.7, 2e-3, -5e-4, 0.3, -0.2, 0.1, 0.05])
    y = plant.reset(x0)
    assert y.names == ("theta1", "theta2", "q21", "q22")
    truth = plant.truth()
    np.testing.assert_allclose(truth.theta, x0[:2], atol=1e-12)
    np.testing.assert_allclose(truth.theta_dot, x0[4:6], atol=1e-7)
    np.testing.assert_allclose(truth.q, x0[2:4], rtol=2e-3)  # the inextensible placement
    tip1 = 0.4 * np.array([np.cos(0.4), np.sin(0.4)])
    np.testing.assert_allclose(truth.tip_positions[0], tip1, atol=1e-12)
    reduced = ReducedPlant(RIGID_FLEXIBLE, kinematics="exact")
    reduced.reset(x0)
    np.testing.assert_allclose(truth.tip_positions[1], reduced.truth().tip_positions[1],
                               atol=2e-5)  # the FE curve's interpolation
    assert truth.tip_deflections[0] == 0.0 and truth.projection_residual[0] == 0.0
    assert truth.tip_deflections[1] == pytest.approx(reduced.truth().tip_deflections[1],
                                                     rel=2e-3)
    vector = plant.truth_vector()
    back = true_state_from_vector(truth.time, vector, 2)
    np.testing.assert_array_equal(back.tip_positions, truth.tip_positions)
    np.testing.assert_array_equal(vector[-4:], [*vector[:2], *vector[4:6]])  # no drives
    np.testing.assert_array_equal(plant.tip_positions(), truth.tip_positions)


def test_mesh_counts_are_for_the_flexible_links():
    """One number for every flexible link, or one count per flexible link; a count for a
    rigid link (a list as long as all links) is refused, naming the key."""
    assert Mesh().counts(RIGID_FLEXIBLE) == (0, 4)
    assert Mesh(elements_per_link=[8]).counts(RIGID_FLEXIBLE) == (0, 8)
    assert Mesh(elements_per_link=(3, 5)).counts(ArmParameters()) == (3, 5)
    with pytest.raises(FieldError, match="elements_per_link gives 2 counts.*flexible links "
                                         "are 2"):
        Mesh(elements_per_link=(4, 4)).counts(RIGID_FLEXIBLE)
    with pytest.raises(FieldError, match="elements_per_link"):
        ExudynPlant(RIGID_FLEXIBLE, mesh=Mesh(elements_per_link=(4, 4)))
    with pytest.raises(FieldError, match="elements_per_link"):
        Mesh(elements_per_link=[4, 0])


def test_drives_and_friction_on_every_joint_of_a_three_link_arm():
    """Drives with friction on all three joints of a rigid–flexible–rigid arm: each motor
    reads its rotor against its stator (the rigid link 1's body for joint 2), and with
    the arm at rest and no torque nothing moves (every bristle stuck, every gear
    unloaded)."""
    joint = Joint(coulomb=0.1, breakaway=0.15, stribeck_velocity=0.01, viscous=0.05,
                  gear_stiffness=5e3, gear_damping=2.0, rotor_inertia=0.05)
    arm = ArmParameters(
        links=(rigid(0.4, 2.0, hub_mass=1.0, hub_inertia=0.05, stator_inertia=0.01),
               flexible(0.5, 1.0, 10.0, modes=2, hub_mass=0.5, hub_inertia=0.02,
                        stator_inertia=0.01, bending_damping=2e-3),
               rigid(0.3, 1.0, hub_mass=0.3, hub_inertia=0.01)),
        joints=(joint,) * 3, payload=Payload(mass=0.1, inertia=1e-4))
    plant = ExudynPlant(arm, step=2.5e-4)
    assert plant.encoder_side == ("motor",) * 3
    x0 = np.zeros(plant.state_size)
    x0[:3] = [0.3, -0.5, 0.8]
    plant.reset(x0)
    for _ in range(50):
        plant.step(np.zeros(3))
    vector = plant.truth_vector()
    np.testing.assert_allclose(vector[:3], x0[:3], atol=1e-9)
    np.testing.assert_allclose(vector[-6:-3], x0[:3], atol=1e-9)  # motors on their hubs
    for _ in range(100):  # above breakaway on joint 3: it turns, motor leading the hub
        plant.step(np.array([0.0, 0.0, 0.5]))
    vector = plant.truth_vector()
    assert vector[2] - x0[2] > 1e-3 and vector[-4] > vector[2]


def test_locked_joints_leave_the_flexible_link_clamped():
    """Both joints of the rigid–flexible arm locked at (0.3, −0.5) rad (clamps through
    the rigid body's turned joint frames): the arm's frequencies are link 2's, clamped
    with the payload at its tip — the reduced model's clamped-mass modes (its own
    frequency equation).  Measured, ANCF 16 el/link: 4e-8, 1.8e-6, 9.4e-6."""
    from reduced_model import LinkModes
    f = natural_frequencies(RIGID_FLEXIBLE, Mesh(elements_per_link=16), theta=(0.3, -0.5),
                            joints="locked", n=3)
    clamped = LinkModes(L=0.5, rho=1.0, EI=10.0, tip_mass=0.1, tip_inertia=5e-4, n=4)
    np.testing.assert_allclose(f, clamped.frequencies_hz[:3], rtol=5e-5)


# --- three links: the FE arm against the exact kinematics ----------------------------------------
#: A rigid upper arm and two flexible links: the torque pulses bend link 2 by up to 4.0 %
#: of its length and link 3 by 2.0 % (tip deflections, measured).
THREE_LINKS = ArmParameters(
    links=(rigid(0.3, 2.0, hub_mass=1.0, hub_inertia=0.05, stator_mass=0.2,
                 stator_inertia=0.005),
           flexible(0.5, 0.5, 4.0, bending_damping=1e-3, hub_mass=0.3, hub_inertia=0.005,
                    stator_mass=0.1, stator_inertia=0.002),
           flexible(0.4, 0.4, 2.0, bending_damping=1e-3, hub_mass=0.2, hub_inertia=0.002)),
    payload=Payload(mass=0.1, inertia=1e-4))


def three_pulses(t):
    return np.array([1.35 * (0.05 <= t < 0.25) - 1.35 * (0.45 <= t < 0.6),
                     -0.45 * (0.1 <= t < 0.3) + 0.45 * (0.5 <= t < 0.7),
                     0.18 * (0.15 <= t < 0.35) - 0.18 * (0.6 <= t < 0.75)])


@pytest.mark.slow
def test_three_links_follow_the_exact_kinematics():
    """Rigid, flexible, flexible under open-loop torque pulses over 1 s: the FE arm
    (ANCF 16 el/link, 125 µs) against the reduced plant with exact kinematics and 4
    modes per flexible link (RK4 at 62.5 µs: 3e-10 rad from 125 µs).  The FE arm is
    converged: 32 el/link move θ by ≤ 5e-7 rad (5.1e-8, 7.8e-8, 1.7e-7 at the same
    Newton tolerance; 32 el/link need 1e-5, 1e-6 being below their round-off at rest),
    62.5 µs by ≤ 3.6e-6 rad.  Measured max |Δθ| to the exact kinematics: 5.2e-7, 5.5e-6,
    8.7e-6 rad; the paper's linear kinematics are 3.6e-4, 9.5e-3 and 1.0e-2 rad away
    (the known-bad this test tells apart)."""
    fe = joint_angles(ExudynPlant(THREE_LINKS, mesh=Mesh(elements_per_link=16),
                                  step=1.25e-4), three_pulses)
    finer = joint_angles(ExudynPlant(THREE_LINKS, mesh=Mesh(elements_per_link=32),
                                     step=1.25e-4, newton_tolerance=1e-5), three_pulses)
    exact, linear = (joint_angles(ReducedPlant(THREE_LINKS, kinematics=kinematics,
                                               modes_per_link=(0, 4, 4), step=6.25e-5),
                                  three_pulses) for kinematics in ("exact", "linear"))
    assert np.all(np.abs(fe - finer).max(axis=0) < 2e-6)
    assert np.all(np.abs(fe - exact).max(axis=0) < 1e-4)  # the bound
    assert np.all(np.abs(fe - linear).max(axis=0)[1:] > 1e-3)


def test_linear_model_and_frequencies_of_a_rigid_flexible_arm():
    """The FE linearisation of an arm with a rigid link: N = 2 inputs, the outputs named
    for modes (0, 2), two rigid-body modes at exactly 0, the flexible poles' |p| at the
    free arm's natural frequencies (Exudyn's eigenvalues of the same FE model; measured
    9e-11 relative); in gravity the undeformed arm is not at rest: refused."""
    from plant_exudyn import linear_model
    from reduced_model import output_names
    sys_ = linear_model(RIGID_FLEXIBLE)
    assert sys_.input_labels == ["tau1", "tau2"]
    assert tuple(sys_.output_labels) == output_names((0, 2))
    poles = np.linalg.eigvals(sys_.A)
    assert np.sum(poles == 0.0) == 4  # two rigid modes: a double pole at 0 each
    flexible_hz = np.sort(np.abs(poles[poles.imag > 0]))[:3] / (2 * np.pi)  # |p| = ω_n
    free = natural_frequencies(RIGID_FLEXIBLE, joints="free", n=3)
    np.testing.assert_allclose(flexible_hz, free, rtol=1e-6)
    rigid_zero = natural_frequencies(RIGID_FLEXIBLE, joints="free", n=2, include_rigid=True)
    assert np.all(rigid_zero < 1e-2)  # the SVD nullspace leaves them at ~1e-4 Hz
    with pytest.raises(ValueError, match="gravity"):
        linear_model(RIGID_FLEXIBLE.replace(gravity=(0.0, -G)))


#: Four links, flexible and rigid in turn, in a vertical plane.
FOUR_LINKS = ArmParameters(
    links=(flexible(0.4, 1.0, 10.0, modes=2, hub_mass=1.0, hub_inertia=0.05, stator_mass=0.2,
                    stator_inertia=0.01, bending_damping=2e-3),
           rigid(0.3, 1.5, hub_mass=0.5, hub_inertia=0.02, stator_mass=0.1,
                 stator_inertia=0.005),
           flexible(0.35, 0.6, 5.0, modes=2, hub_mass=0.3, hub_inertia=0.01,
                    stator_inertia=0.003, bending_damping=1e-3),
           rigid(0.25, 1.0, hub_mass=0.2, hub_inertia=0.005)),
    payload=Payload(mass=0.1, inertia=1e-4), gravity=(0.0, -G))


@pytest.mark.parametrize("mesh", [Mesh(), Mesh("geometrically_exact", 16)],
                         ids=["ancf", "ge"])
def test_four_links_in_gravity_report_and_move_as_the_reduced_plant(mesh):
    """A flexible–rigid–flexible–rigid arm in a vertical plane, placed at a deflected,
    moving state: its whole truth vector (θ, q, rates, every tip, deflection, residual
    and motor) is the reduced plant's with exact kinematics (measured 5e-11: the FE
    links lie on the modal curves), and 0.2 s of torques in gravity later the joint
    angles agree to 4.4e-5 rad (ANCF 4 el/link; GE 16: 6.2e-5; the 2-mode model's
    truncation and the 0.25 ms step)."""
    x0 = np.zeros(16)
    x0[:4], x0[4:8] = (0.2, -0.3, 0.5, -0.4), (1e-3, -2e-4, -5e-4, 1e-4)
    x0[8:12] = (0.3, -0.2, 0.4, 0.1)
    fe = ExudynPlant(FOUR_LINKS, mesh=mesh, step=2.5e-4)
    reduced = ReducedPlant(FOUR_LINKS, kinematics="exact", step=2.5e-4)
    fe.reset(x0)
    reduced.reset(x0)
    np.testing.assert_allclose(fe.truth_vector(), reduced.truth_vector(), atol=1e-9)
    gap = 0.0
    for k in range(200):
        tau = np.array([0.5, -0.3, 0.2, 0.1]) * np.sin(0.03 * k)
        fe.step(tau)
        reduced.step(tau)
        gap = max(gap, np.abs(fe.truth_vector()[:4] - reduced.truth_vector()[:4]).max())
    assert gap < 2e-4
    assert np.abs(fe.truth_vector()[:4] - x0[:4]).max() > 0.2  # it moved: 0.29 rad
