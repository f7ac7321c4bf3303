"""Verdicts: the paper's claims, the sampled-data stability map, attribution and regression bounds."""
