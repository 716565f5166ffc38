"""``python -m houghcad.synth``: write the demo cloud (:func:`houghcad.synth.write_demo`).

It writes ``demo_part.ply`` (binary PLY, x y z) and its Fit4CAD ground truth
``demo_part_primitives.txt`` into ``-o DIR``, or, with ``--package-data``, over the copies bundled
in houghcad's ``data`` folder (which ``houghcad demo`` segments; a maintainer regenerates them
after changing the generator). Nothing is written without one of the two.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from .parts import write_demo

#: File name of the demo cloud; its ground truth is ``<stem>_primitives.txt`` beside it.
NAME = "demo_part.ply"
#: The package's data folder (where :func:`~houghcad.synth.write_demo` writes by default).
DATA = Path(__file__).resolve().parent.parent / "data"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m houghcad.synth",
        description=f"Generate the demo part (block_with_hole_and_slot, seed 7, 12000 points, noise 0.001) and "
        f"write {NAME} (binary PLY, x y z) and its Fit4CAD ground truth demo_part_primitives.txt. "
        "Nothing is written without -o or --package-data.")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("-o", "--output", metavar="DIR", type=Path,
                       help="write the two files into DIR (created if needed)")
    where.add_argument("--package-data", action="store_true",
                       help="replace the copies bundled in houghcad's data folder "
                       f"({DATA}), which `houghcad demo` segments")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.package_data:
        path = DATA / NAME
    else:
        if args.output.exists() and not args.output.is_dir():
            print(f"python -m houghcad.synth: error: {args.output}: not a folder", file=sys.stderr)
            return 2
        try:
            args.output.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            print(f"python -m houghcad.synth: error: {args.output}: cannot create the folder "
                  f"({exc.strerror or exc})", file=sys.stderr)
            return 2
        path = args.output / NAME
    try:
        write_demo(path)  # both files atomically
    except OSError as exc:
        print(f"python -m houghcad.synth: error: {path.parent}: cannot write ({exc.strerror or exc})", file=sys.stderr)
        return 2
    print(f"wrote {path} and {path.with_name(path.stem + '_primitives.txt')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
