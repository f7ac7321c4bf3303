"""The ``flexarm`` command line: a thin layer over the library.

Errors in user input end with one line on stderr and exit status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import sys
from importlib.metadata import version

import numpy as np

from plant_exudyn import ELEMENTS, Mesh, natural_frequencies
from reduced_model import ArmModel, ArmParameters, validate_modes_per_link

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, status 2 (argparse's own convention)
        self.exit(EXIT_USAGE, f"flexarm: error: {message}\n")


def _int_in(lo: int, hi: int):
    """argparse type: an integer in [lo, hi]."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be in {lo}..{hi}, got {value}")
        return value
    return parse


def _format_row(label: str, values) -> str:
    return f"  {label:<30}" + "".join(f"{v:>11.4f}" for v in values)


def cmd_modes(args: argparse.Namespace) -> int:
    if args.params and args.table1:
        raise ValueError("--params and --table1 exclude each other")
    if args.table1:
        params, source = ArmParameters.table1(), "the paper's Table 1 (no stator, no damping)"
    elif args.params:
        params, source = ArmParameters.from_toml(args.params), args.params
    else:
        params, source = ArmParameters(), "defaults (Table 1 + stator inertia + damping)"
    model = ArmModel(params, validate_modes_per_link(args.modes_per_link, where="--modes-per-link"))
    mesh = Mesh(element=args.element, elements_per_link=args.elements) if args.compare else None
    n1, n2 = model.modes_per_link
    print(f"Reduced model, {n1}+{n2} clamped-mass modes, parameters: {source}")
    print("Clamped-mass link frequencies [Hz]")
    for i, modes in enumerate(model.mode_shapes, start=1):
        print(_format_row(f"link {i}", modes.frequencies_hz))
    for theta2 in args.theta2:
        Q = np.zeros(model.n)
        Q[1] = theta2
        print(f"Coupled frequencies at theta1 = 0, theta2 = {theta2:g} rad [Hz]")
        for joints in ("locked", "free"):
            reduced = model.natural_frequencies(Q, joints)
            label = "joints locked" if joints == "locked" else "joints free (non-zero)"
            print(_format_row(label + (" reduced" if mesh else ""), reduced))
            if mesh:
                fe = natural_frequencies(params, mesh, theta=(0.0, theta2), joints=joints,
                                         n=len(reduced))
                print(_format_row(f"{'':<14}FE", fe))
                print(_format_row(f"{'':<10}gap [%]", 100 * (reduced - fe) / fe))
    if mesh:
        print(f"FE: {mesh.element}, {mesh.elements_per_link[0]}+{mesh.elements_per_link[1]} "
              "elements; gap = (reduced - FE) / FE")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="flexarm", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version",
                        version=f"flexarm-validation {version('flexarm-validation')}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    modes = sub.add_parser("modes", help="natural frequencies of the reduced model")
    modes.add_argument("--params", metavar="TOML",
                       help="arm parameters (top-level keys or a [params] table)")
    modes.add_argument("--table1", action="store_true",
                       help="the paper's Table 1 exactly (no stator inertia, no damping)")
    modes.add_argument("--modes-per-link", nargs=2, type=int, default=[2, 2],
                       metavar=("N1", "N2"), help="assumed modes of link 1 and 2 (1..4)")
    modes.add_argument("--theta2", nargs="+", type=float, default=[0.0], metavar="RAD",
                       help="joint-2 angles at which to linearise (default 0)")
    modes.add_argument("--compare", action="store_true",
                       help="also print the Exudyn FE model's frequencies and the gap")
    modes.add_argument("--element", choices=ELEMENTS, default="ancf",
                       help="FE beam element for --compare (default ancf)")
    modes.add_argument("--elements", type=_int_in(1, 64), default=4, metavar="N",
                       help="FE elements per link for --compare (default 4)")
    modes.set_defaults(func=cmd_modes)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as exc:
        print(f"flexarm: error: {exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
