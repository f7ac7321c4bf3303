"""
Is the reduced model good enough for control?  The ν-gap
========================================================

Close natural frequencies do not say that a model is good enough to design a controller
on.  The ν-gap δν between the reduced model and the FE arm, set against the stability
margin b of the loop, does: if δν < b, the controller that stabilises the reduced model
stabilises the FE arm too.  Here the PBC's loop broken at the plant input, on the
default arm, over the elbow angle θ2 — what ``flexarm validity`` computes per case.
"""
import matplotlib.pyplot as plt
import numpy as np

from controllers import PassivityBasedController
from plant_exudyn import Mesh, linear_model
from reduced_model import ArmModel, ArmParameters
from validation import law_gain, nu_gap, reduced_linear_model, stability_margin

model = ArmModel(ArmParameters())                 # the default arm, 2+2 modes
states = list(model.state_names)                  # theta1, theta2, q11, ..., q22_dot
Ts = 1e-3
theta2 = np.linspace(0.0, np.pi, 4)
gaps, margins = [], []
for t2 in theta2:
    P = reduced_linear_model(model, theta=(0.0, t2), Ts=Ts)          # exact ZOH
    F = linear_model(ArmParameters(), Mesh(), theta=(0.0, t2), Ts=Ts,
                     model=model)                                    # the FE arm, same outputs
    # The PBC (eq. 20) linearised about a resting point: δτ = −K δx.
    x = np.zeros(2 * model.n)
    x[1] = t2
    K = law_gain(PassivityBasedController(model, Ts=1e-3), x, 0.0,
                 lambda t: (x[:2].copy(), np.zeros(2), np.zeros(2)))
    gaps.append(nu_gap(K * P[states, :], K * F[states, :]))
    margins.append(stability_margin(K * P[states, :], np.eye(2)))
    print(f"θ2 = {t2:4.2f} rad: FE states {F.nstates}, δν = {gaps[-1]:.3f}, "
          f"b = {margins[-1]:.3f}: {'certified' if gaps[-1] < margins[-1] else 'not certified'}")

# %%
# The frequency responses τ2 → θ2 of both linear models at θ2 = 0 (continuous time):
# where they part, the reduced model is missing what the FE arm has.
P = reduced_linear_model(model, theta=(0.0, 0.0))
F = linear_model(ArmParameters(), Mesh(), theta=(0.0, 0.0), model=model)
w = 2 * np.pi * np.logspace(-0.5, 2.5, 600)
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8))
for system, label, style in ((P, "reduced 2+2", dict(lw=4, alpha=0.35)),
                             (F, "FE (ANCF 4+4)", dict(lw=1.2))):
    response = system["theta2", "tau2"].frequency_response(w)
    ax1.loglog(w / (2 * np.pi), np.squeeze(response.magnitude), label=label, **style)
ax1.set_xlabel("frequency [Hz]")
ax1.set_ylabel("|θ2 / τ2| [rad/(N m)]")
ax1.legend()
ax2.plot(theta2, gaps, "o-", label="δν(K P_reduced, K P_FE)")
ax2.plot(theta2, margins, "s--", label="b(K P_reduced, I)")
ax2.set_xlabel("θ2 [rad]")
ax2.set_title(f"PBC loop at Ts = {Ts * 1e3:g} ms: certified where δν < b", fontsize=10)
ax2.legend(fontsize=8)
fig.tight_layout()
