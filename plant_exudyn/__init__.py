"""The truth plant: the two-link flexible arm as an Exudyn flexible multibody model.

Both links are ANCF cable elements (default) or geometrically exact 2D beams, built from
the same `reduced_model.ArmParameters` as the reduced model; the deflection field is
projected onto the reduced model's mode shapes so that both plants report the same
coordinates.  Implements the Plant interface of DESIGN.md.
"""
