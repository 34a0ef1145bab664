"""Command line ``grasp_apso_urdf``: write the hand description as a URDF.

Examples::

    grasp_apso_urdf                         # the shipped hand's URDF on stdout
    grasp_apso_urdf --out urdf/             # writes urdf/apso_paper_hand.urdf
    grasp_apso_urdf --hand my_hand.yaml --out /tmp

Exit status: 0 on success, 2 for a bad hand file or an unwritable output directory.
Also runnable as ``python -m grasp_apso.tools.urdf_cli``.
"""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

from ..model.hand import load_hand
from ..model.urdf import hand_to_urdf, write_urdf

PROG = "grasp_apso_urdf"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Generate the URDF of a hand description (YAML). Without --out the URDF "
                    "is printed on stdout.",
    )
    parser.add_argument("--hand", metavar="FILE", default=None,
                        help="hand description YAML (default: the shipped paper hand)")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="write <DIR>/<hand name>.urdf instead of printing")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (0 ok, 2 bad input)."""
    args = _parser().parse_args(argv)
    try:
        hand = load_hand(args.hand)
        if args.out is None:
            sys.stdout.write(hand_to_urdf(hand))
            return 0
        path = write_urdf(hand, args.out)
    except ValueError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
