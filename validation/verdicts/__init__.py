"""Verdicts: closed-loop mesh convergence of the truth plant, the paper's claims, the
sampled-data stability map, attribution, regression bounds, and the reduced model's linear
validity (ν-gap, predicted and certified stability)."""
