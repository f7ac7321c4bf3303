"""Verdicts: closed-loop mesh convergence of the truth plant, the paper's claims, the
sampled-data stability map, attribution and regression bounds."""
