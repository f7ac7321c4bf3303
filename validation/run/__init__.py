"""One run: a scenario, its laws, the closed loop and its compiled sample, the result and its metrics."""
