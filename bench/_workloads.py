"""Workloads several benches measure, defined once so that their numbers compare."""

#: The command line of the tree in the current directory, in a fresh interpreter:
#: ``python -c CLI ARGS`` (works for revisions whose CLI predates the console script).
CLI = "import sys; from validation.cli import main; raise SystemExit(main(sys.argv[1:]))"

#: 48 × 5 s reduced runs (PBC with two SMOs, six payloads, four seeds).
REDUCED_48 = """name = "bench-reduced"
[scenario]
duration = 5.0
observer.kind = "smo-paper"
[[sweep]]
grid."true_params.Mp" = [0.0, 0.1, 0.2, 0.3, 0.5, 0.8]
grid."observer.kind" = ["smo-paper", "smo-bl"]
grid.seed = [1, 2, 3, 4]
"""

#: 8 × 20 s truth-plant runs (PBC + sign SMO, four payloads, two seeds).
TRUTH_8 = """name = "bench-exudyn"
[scenario]
plant.kind = "exudyn"
observer.kind = "smo-paper"
[[sweep]]
grid."true_params.Mp" = [0.0, 0.1, 0.5, 1.0]
grid.seed = [1, 2]
"""

#: 48 × 5 s reduced runs of one law pair (PBC + sign SMO: six payloads, eight seeds), so
#: that a one-run campaign of the same laws is their fair start (the kernels it loads are
#: all the campaign needs).
REDUCED_ONE_LAW = """name = "bench-coordinator"
[scenario]
duration = 5.0
observer.kind = "smo-paper"
[[sweep]]
grid."true_params.Mp" = [0.0, 0.1, 0.2, 0.3, 0.5, 0.8]
grid.seed = [1, 2, 3, 4, 5, 6, 7, 8]
"""

#: One run of `REDUCED_ONE_LAW`'s laws: its campaign is the command's fixed start.
ONE_RUN = """name = "bench-one"
[scenario]
duration = 5.0
observer.kind = "smo-paper"
"""
