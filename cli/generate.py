"""``eosp generate [--fleet] ...``: draw a problem with the generator of the kind the command line selects and
write it (a single pass: an interchange directory; a fleet: a fleet directory)."""

from __future__ import annotations

import argparse

from eosp.problem import load


def cmd_generate(kind, ns: argparse.Namespace) -> int:
    gen = kind.generator(ns)
    print(load(gen.generate)(kind.generator_config(gen, ns), ns.out, overwrite=ns.overwrite))
    return 0
