"""Validation: the closed loop, metrics, scenarios and campaigns, reports, and the
``flexarm`` command line.  Nothing else in the project imports this package.
"""
